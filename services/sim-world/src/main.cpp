#include "sim_world_service.hpp"

int main(int argc, char** argv) {
  return cell::service::run<cell::sim_world::SimWorldConfig, cell::sim_world::SimWorldService>(
      argc, argv,
      {.kind = "sim-world",
       .summary = "cell world simulator: parts, belts, photocells and the grippers that take "
                  "them; publishes the ground truth",
       .default_config = "config/sim-world.yaml"},
      &cell::sim_world::load_config);
}
