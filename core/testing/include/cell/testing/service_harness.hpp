#pragma once

#include <memory>
#include <string>
#include <thread>

#include "cell/bus/participant.hpp"
#include "cell/service/runtime.hpp"

namespace cell::testing {

/// Runs one service in-process on a test's private bus (its own participant on `domain` and
/// `partition`), its run() on a thread, for tests against cell_<svc>_lib. The destructor
/// requests the stop, joins, and tears the service down in the framework's order.
/// Each harness has its own stop request (a ShutdownSignal it only ever triggers itself).
template <typename Config, typename Service>
class ServiceHarness {
 public:
  ServiceHarness(std::uint32_t domain, std::string partition, Config config, std::string_view kind)
      : shutdown_(std::make_unique<service::ShutdownSignal>()),
        config_(std::move(config)),
        participant_(domain, std::move(partition)) {
    if (config_.common.service_id.empty()) {
      config_.common.service_id = std::string(kind);
    }
    info_.kind = kind;
    ctx_ = std::make_unique<service::Context>(participant_, config_.common, info_, *shutdown_);
    service_ = std::make_unique<Service>(*ctx_, config_);
    thread_ = std::thread([this] { service_->run(*ctx_); });
  }
  ~ServiceHarness() {
    shutdown_->request();
    thread_.join();
    service_.reset();
    ctx_.reset();
  }
  ServiceHarness(const ServiceHarness&) = delete;
  ServiceHarness& operator=(const ServiceHarness&) = delete;

  Service& service() { return *service_; }
  service::Context& context() { return *ctx_; }
  const bus::Participant& participant() const { return participant_; }

 private:
  std::unique_ptr<service::ShutdownSignal> shutdown_;
  Config config_;
  service::ServiceInfo info_{};
  bus::Participant participant_;
  std::unique_ptr<service::Context> ctx_;
  std::unique_ptr<Service> service_;
  std::thread thread_;
};

}  // namespace cell::testing
