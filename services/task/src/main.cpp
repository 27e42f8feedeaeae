#include "task_service.hpp"

int main(int argc, char** argv) {
  return cell::service::run<cell::task_service::TaskConfig, cell::task_service::TaskService>(
      argc, argv,
      {.kind = "task",
       .summary = "cell task service: durable pick/place jobs on the table and on the conveyor, "
                  "from remote clients, journaled and resumed after a restart",
       .default_config = "config/task.yaml"},
      &cell::task_service::load_config);
}
