#pragma once
// The names of the job states (idl/task.idl JobState) as every client shows them.

#include <string_view>

#include "task.h"

namespace cell::task {

/// "queued", "rejected", "running", "paused", "succeeded", "failed", "cancelled".
constexpr std::string_view job_state_name(int state) noexcept {
  switch (state) {
    case cell_task_JOB_QUEUED:
      return "queued";
    case cell_task_JOB_REJECTED:
      return "rejected";
    case cell_task_JOB_RUNNING:
      return "running";
    case cell_task_JOB_PAUSED:
      return "paused";
    case cell_task_JOB_SUCCEEDED:
      return "succeeded";
    case cell_task_JOB_FAILED:
      return "failed";
    case cell_task_JOB_CANCELLED:
      return "cancelled";
    default:
      return "unknown";
  }
}

}  // namespace cell::task
