#include "gateway_service.hpp"

int main(int argc, char** argv) {
  return cell::service::run<cell::gateway::GatewayConfig, cell::gateway::GatewayService>(
      argc, argv,
      {.kind = "gateway",
       .summary = "cell robot gateway: runs one robot's servo loop and executes trajectories, "
                  "ALTER corrections and commands",
       .default_config = "config/gateway-ibm7545.yaml"},
      &cell::gateway::load_config);
}
