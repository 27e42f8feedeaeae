#!/usr/bin/env bash
# The run command: installs what is missing, builds, starts the whole simulated cell on this
# machine (every service and simulator of deploy/local.yaml), then runs the example table job
# on it (config/jobs/table_ics.yaml: the 1994 thesis's 15 ICs to their slots, a progress bar,
# then the job's result) and keeps the cell running in the foreground. Ctrl-C (or
# `build/bin/cell down` from another terminal) stops it.
#
# Usage: scripts/cell-up.sh [--job FILE | --no-job] [cell up args, e.g. --detach]
#   --job FILE  run another job file once the cell is up (config/jobs/ has one of each kind)
#   --no-job    only the cell (so does `--host NAME`: one PC's share runs no job by itself)
#   --detach    start the cell in the background, run the job, return (its exit code)
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"

job="$root/config/jobs/table_ics.yaml"
detach=0
up_args=()
while [ $# -gt 0 ]; do
  case "$1" in
    --job)
      [ $# -ge 2 ] || { echo "cell-up.sh: --job needs a job file" >&2; exit 2; }
      job="$2"
      shift 2
      continue
      ;;
    --no-job) job="" ;;
    --host | --host=*) job="" ; up_args+=("$1") ;;
    --detach) detach=1 ; up_args+=("$1") ;;
    *) up_args+=("$1") ;;
  esac
  shift
done
if [ -n "$job" ] && [ ! -f "$job" ]; then
  echo "cell-up.sh: job file '$job' not found" >&2
  exit 2
fi

"$root/scripts/install-deps.sh"
"$root/scripts/build.sh"
build="${CELL_BUILD_DIR:-$root/build}"
export CELL_HOME="$root"
cellctl="$build/bin/cellctl"

if [ -z "$job" ]; then
  exec "$build/bin/cell" up "${up_args[@]}"
fi

# Waits for the task service to answer (the cell's services start in dependency order), then
# submits the job and follows it to its end. Its exit code: cellctl submit --wait's (0: done).
run_job() {
  local waited=0
  until "$cellctl" jobs >/dev/null 2>&1; do
    if [ "$waited" -ge 120 ]; then
      echo "cell-up.sh: the task service did not answer within 120 s (build/bin/cell status," \
           "run/logs/task.log); the job was not submitted" >&2
      return 1
    fi
    sleep 1
    waited=$((waited + 1))
  done
  echo "cell-up.sh: the cell is up; running the job in $job" >&2
  "$cellctl" submit "$job" --wait
}

if [ "$detach" -eq 1 ]; then
  "$build/bin/cell" up "${up_args[@]}"
  run_job
  exit $?
fi

"$build/bin/cell" up "${up_args[@]}" &
cell_pid=$!
stopping=0
stop_cell() {
  stopping=1
  kill -INT "$cell_pid" 2>/dev/null || true
}
trap stop_cell INT TERM
if run_job; then
  echo "cell-up.sh: the job is done; the cell keeps running (Ctrl-C stops it)" >&2
elif [ "$stopping" -eq 0 ]; then
  echo "cell-up.sh: the job did not succeed (above); the cell keeps running (Ctrl-C stops it)" >&2
fi
set +e
wait "$cell_pid"
rc=$?
# A signal interrupts the first wait: wait again for the cell's orderly shutdown.
while kill -0 "$cell_pid" 2>/dev/null; do
  wait "$cell_pid"
  rc=$?
done
exit "$rc"
