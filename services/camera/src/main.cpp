#include "camera_service.hpp"

int main(int argc, char** argv) {
  return cell::service::run<cell::camera::CameraConfig, cell::camera::CameraService>(
      argc, argv,
      {.kind = "camera",
       .summary = "cell camera service: publishes images of one camera (the simulated renderer, "
                  "replayed image files or a real device), free-running, photocell-triggered "
                  "or on request, with ground truth for simulated frames",
       .default_config = "config/camera-ibm7545.yaml"},
      &cell::camera::load_config);
}
