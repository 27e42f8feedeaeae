#include "motion_service.hpp"

int main(int argc, char** argv) {
  return cell::service::run<cell::motion_service::MotionConfig,
                            cell::motion_service::MotionService>(
      argc, argv,
      {.kind = "motion",
       .summary = "cell motion service: plans moves, picks, places and tracking for the cell's "
                  "robots and hands the trajectories to their gateways",
       .default_config = "config/motion.yaml"},
      &cell::motion_service::load_config);
}
