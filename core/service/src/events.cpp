#include "cell/service/events.hpp"

#include "cell/bus/view.hpp"
#include "cell/common/log.hpp"
#include "cell/common/time.hpp"

namespace cell::service {

EventPublisher::EventPublisher(const bus::Participant& participant, std::string source)
    : source_(std::move(source)),
      topic_(participant, bus::topics::kCellEvent),
      writer_(participant, topic_, bus::topics::kCellEvent) {}

void EventPublisher::publish(cell_health_Severity severity, std::string_view code,
                             std::string_view text, std::string_view robot_id,
                             std::string_view job_id) {
  const std::string code_s(code);
  const std::string text_s(text);
  const std::string robot_s(robot_id);
  const std::string job_s(job_id);
  const log::Level level = severity == cell_health_SEVERITY_INFO      ? log::Level::kInfo
                           : severity == cell_health_SEVERITY_WARNING ? log::Level::kWarn
                                                                      : log::Level::kError;
  log::write(level, "cell_event", text_s, {{"code", code_s}, {"robot", robot_s}, {"job", job_s}});
  cell_health_CellEvent event{};
  event.header.stamp_ns = wall_time_ns();
  event.header.frame_id = bus::borrow(source_);
  event.header.seq = ++seq_;
  event.source = bus::borrow(source_);
  event.severity = severity;
  event.code = bus::borrow(code_s);
  event.text = bus::borrow(text_s);
  event.robot_id = bus::borrow(robot_s);
  event.job_id = bus::borrow(job_s);
  if (auto status = writer_.write(event); !status) {
    log::warn("cell_event", status.error().message);
  }
}

}  // namespace cell::service
