#include "image_bus.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <thread>
#include <vector>

#include <fmt/format.h>

#include "cell/bus/qos.hpp"
#include "cell/bus/reader.hpp"
#include "cell/bus/topic.hpp"
#include "cell/bus/view.hpp"
#include "cell/bus/writer.hpp"
#include "cell/common/time.hpp"
#include "cell/process/child.hpp"

namespace cell::bench {
namespace {

bus::Qos image_qos(bool reliable) {
  return reliable ? bus::qos::reliable_stream(2) : bus::make_qos(bus::topics::kImage);
}

}  // namespace

int image_publisher(const ImageBusOptions& o) {
  try {
    bus::Participant participant(o.domain, o.partition);
    bus::Topic<cell_vision_Image> topic(participant, bus::topics::kImage);
    const bus::Qos qos = image_qos(o.reliable);
    bus::Writer<cell_vision_Image> writer(participant, topic, qos.get());
    if (!writer.wait_for_readers(1, std::chrono::seconds(10))) {
      std::fprintf(stderr, "image-pub: no reader within 10 s\n");
      return 1;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(500));  // the reader's side matches
    std::vector<std::uint8_t> pixels(static_cast<std::size_t>(o.width) * o.height);
    const std::string camera = "bench_cam";
    const std::string mono8 = "mono8";
    const std::string empty;
    const auto period = std::chrono::nanoseconds(static_cast<std::int64_t>(1e9 / o.rate_hz));
    auto next = std::chrono::steady_clock::now();
    for (int i = 1; i <= o.count; ++i) {
      std::fill(pixels.begin(), pixels.end(), static_cast<std::uint8_t>(i));
      cell_vision_Image img{};
      img.camera_id = bus::borrow(camera);
      img.request_id.client_id = bus::borrow(empty);
      img.header.seq = static_cast<std::uint64_t>(i);
      img.header.frame_id = bus::borrow(camera);
      img.width_px = static_cast<std::uint32_t>(o.width);
      img.height_px = static_cast<std::uint32_t>(o.height);
      img.encoding = bus::borrow(mono8);
      img.step_bytes = static_cast<std::uint32_t>(o.width);
      bus::borrow(img.data, pixels);
      img.robot_id = bus::borrow(empty);
      img.belt_id = bus::borrow(empty);
      img.header.stamp_ns = wall_time_ns();
      if (auto s = writer.write(img); !s) {
        std::fprintf(stderr, "image-pub: %s\n", s.error().message.c_str());
        return 1;
      }
      next += period;
      std::this_thread::sleep_until(next);
    }
    std::this_thread::sleep_for(std::chrono::seconds(1));  // let retransmits finish
  } catch (const std::exception& e) {
    std::fprintf(stderr, "image-pub: %s\n", e.what());
    return 1;
  }
  return 0;
}

ImageBusResult run_image_bus(const ImageBusOptions& o) {
  ImageBusResult r;
  r.sent = o.count;
  try {
    bus::Participant participant(o.domain, o.partition);
    bus::Topic<cell_vision_Image> topic(participant, bus::topics::kImage);
    const bus::Qos qos = image_qos(o.reliable);
    bus::Reader<cell_vision_Image> reader(participant, topic, qos.get());
    process::SpawnOptions spawn;
    spawn.executable = o.self_exe;
    spawn.args = {"--role",   "image-pub",
                  "--bus-count", std::to_string(o.count),
                  "--bus-rate",  fmt::format("{}", o.rate_hz),
                  "--bus-qos",   o.reliable ? "reliable" : "stream",
                  "--bus-width", std::to_string(o.width),
                  "--bus-height", std::to_string(o.height),
                  "--domain",    std::to_string(o.domain),
                  "--partition", o.partition};
    auto child = process::Child::spawn(spawn);
    if (!child) {
      r.error = child.error().message;
      return r;
    }
    std::vector<double> latency_ms;
    bool size_ok = true;
    const auto budget = std::chrono::seconds(15) +
                        std::chrono::milliseconds(static_cast<int>(1000.0 * o.count / o.rate_hz));
    const auto deadline = std::chrono::steady_clock::now() + budget;
    while (std::chrono::steady_clock::now() < deadline) {
      (void)reader.wait_for_data(std::chrono::milliseconds(100));
      (void)reader.take_each([&](const cell_vision_Image& img, const dds_sample_info_t&) {
        latency_ms.push_back(static_cast<double>(wall_time_ns() - img.header.stamp_ns) * 1e-6);
        size_ok = size_ok && img.data._length == static_cast<std::uint32_t>(o.width * o.height);
      });
      if (auto exit = child->poll(); exit) {
        // Drain what is still arriving, then stop.
        (void)reader.wait_for_data(std::chrono::milliseconds(200));
        (void)reader.take_each([&](const cell_vision_Image& img, const dds_sample_info_t&) {
          latency_ms.push_back(static_cast<double>(wall_time_ns() - img.header.stamp_ns) * 1e-6);
        });
        if (!exit->exited || exit->code != 0) {
          std::string out;
          (void)child->read_available(out);
          r.error = fmt::format("publisher ended with {}: {}", exit->describe(), out);
        }
        break;
      }
    }
    if (!size_ok) {
      r.error = "an image arrived with the wrong size";
    }
    r.received = static_cast<int>(latency_ms.size());
    if (!latency_ms.empty()) {
      std::sort(latency_ms.begin(), latency_ms.end());
      r.latency_p50_ms = latency_ms[latency_ms.size() / 2];
      r.latency_p99_ms = latency_ms[std::min(latency_ms.size() - 1, latency_ms.size() * 99 / 100)];
      r.latency_max_ms = latency_ms.back();
    }
  } catch (const std::exception& e) {
    r.error = e.what();
  }
  return r;
}

}  // namespace cell::bench
