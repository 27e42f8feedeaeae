#include "echo_service.hpp"

int main(int argc, char** argv) {
  return cell::service::run<cell::echo::EchoConfig, cell::echo::EchoService>(
      argc, argv,
      {.kind = "echo",
       .summary = "cell echo service: heartbeats and answers pings (proves the machinery)",
       .default_config = "config/echo.yaml"},
      &cell::echo::load_config);
}
