#include "sim_excalibur_service.hpp"

int main(int argc, char** argv) {
  return cell::service::run<cell::sim_excalibur::SimExcaliburConfig,
                            cell::sim_excalibur::SimExcaliburService>(
      argc, argv,
      {.kind = "sim-excalibur",
       .summary = "Excalibur controller simulator: the RSI controller's ASCII dialect on a "
                  "pseudo-terminal, with its slowness, unsolicited messages and line noise",
       .default_config = "config/sim-excalibur.yaml"},
      &cell::sim_excalibur::load_config);
}
