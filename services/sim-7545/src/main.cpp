#include <string_view>

#include "servo_limits.hpp"
#include "sim_service.hpp"

int main(int argc, char** argv) {
  if (argc > 1 && std::string_view(argv[1]) == "inject") {
    return cell::sim7545::run_inject(argc - 1, argv + 1);
  }
  if (argc > 1 && std::string_view(argv[1]) == "limits") {
    return cell::sim7545::run_limits(argc - 1, argv + 1);
  }
  return cell::service::run<cell::sim7545::SimConfig, cell::sim7545::SimService>(
      argc, argv,
      {.kind = "sim-7545",
       .summary = "IBM 7545 slave simulator: the 80C196 board's DPR protocol over POSIX shared "
                  "memory, with a joint model the gateway's 1 kHz PD loop servos "
                  "(`cell-sim-7545 inject --help` injects faults; `cell-sim-7545 limits` derives the "
                  "speeds and accelerations the joints can follow)",
       .default_config = "config/sim-7545.yaml"},
      &cell::sim7545::load_config);
}
