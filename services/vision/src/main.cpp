#include "vision_service.hpp"

int main(int argc, char** argv) {
  return cell::service::run<cell::vision::VisionConfig, cell::vision::VisionService>(
      argc, argv,
      {.kind = "vision",
       .summary = "cell vision service: locates parts in every image (Detections, with robot "
                  "poses and clear-grip tests) and measures edges on request (EdgeResult)",
       .default_config = "config/vision.yaml"},
      &cell::vision::load_config);
}
