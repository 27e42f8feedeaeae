#!/usr/bin/env bash
# Table jobs in a row on the cell as shipped: `cell up` of deploy/local.yaml (the IBM 7545 on its
# DPR board's simulator at the thesis's 1 kHz, full speed_scale), config/jobs/table_ics.yaml,
# the world put back to its scene before each job. It counts what the arm did, from the
# simulated board's own log and state, not from the job's report:
#   torque faults   the board's 0x0100-0x0800 (a torque word out of the DAC's range)
#   overrun faults  the board's 0x0001-0x00FF (a joint past its overrun limit)
#   deadline faults the board's 0x1000 / 0x2000 (a master later than the board's grace)
#   link faults     the gateway's "link to the controller failed" (no exchange 4 cycles running)
#   other faults    the gateway's own faults with bits above the board's (0x10000 and up: a
#                   slave that went silent, a procedure that did not finish in time)
#   late periods    periods whose master finished past the board's deadline, served within the
#                   simulator's grace (cellctl robot state: board.late_periods)
#   board behind    how far the simulated board's clock fell behind the host's (the time it
#                   absorbed), from its log
# and, by the world's ground truth (cellctl world parts), how many parts lie in the job's slots.
#
# Usage: bench/table_soak.sh [JOBS (default 20)] [--run-dir DIR (default: a fresh temp dir)]
# Needs the build (scripts/build.sh). Exit 0 only when every job succeeded with 0 faults.
set -uo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="${CELL_BUILD_DIR:-$root/build}"
jobs=20
run_dir=""
while [ $# -gt 0 ]; do
  case "$1" in
    --run-dir) run_dir="$2"; shift 2 ;;
    [0-9]*) jobs="$1"; shift ;;
    *) echo "table_soak.sh: unknown argument '$1'" >&2; exit 2 ;;
  esac
done
[ -n "$run_dir" ] || run_dir="$(mktemp -d /tmp/cell-table-soak-XXXXXX)"
mkdir -p "$run_dir"
export CELL_HOME="$root"
# A private bus, so that a cell already running on this machine is not disturbed.
export CELL_DOMAIN_ID="${CELL_DOMAIN_ID:-$((100 + RANDOM % 100))}"
export CELL_PARTITION="${CELL_PARTITION:-soak-$$}"
cell="$build/bin/cell"
cellctl="$build/bin/cellctl"
job_file="$root/config/jobs/table_ics.yaml"
logs="$run_dir/logs"

stop() { "$cell" down --run-dir "$run_dir" >/dev/null 2>&1 || true; }
trap stop EXIT
echo "table_soak: $jobs table jobs; run dir $run_dir (domain $CELL_DOMAIN_ID)" >&2
if ! "$cell" up --detach --run-dir "$run_dir" >"$run_dir/up.log" 2>&1; then
  echo "table_soak: cell up failed:" >&2
  cat "$run_dir/up.log" >&2
  exit 1
fi
waited=0
until "$cellctl" jobs >/dev/null 2>&1; do
  [ "$waited" -lt 120 ] || { echo "table_soak: no task service within 120 s" >&2; exit 1; }
  sleep 1
  waited=$((waited + 1))
done

count() {  # count FILE REGEX: matching lines (0 when the file is absent)
  if [ -f "$1" ]; then grep -cE "$2" "$1" || true; else echo 0; fi
}
board_faults() {  # board_faults MASK_REGEX: the board's error lines whose bits match
  [ -f "$logs/sim-7545.log" ] || { echo 0; return; }
  grep -E 'msg="error register set"' "$logs/sim-7545.log" |
    sed -n 's/.*bits=0x\([0-9a-f]*\).*/\1/p' | while read -r b; do
      [ $((16#$b & $1)) -ne 0 ] && echo x
    done | wc -l
}

gateway_faults() {  # the gateway's own faults: bits above the board's 16
  [ -f "$logs/gateway.ibm7545.log" ] || { echo 0; return; }
  grep -E "msg=\"robot 'ibm7545' faulted \(bits 0x[0-9a-f]+\)" "$logs/gateway.ibm7545.log" |
    sed -n 's/.*faulted (bits 0x\([0-9a-f]*\)).*/\1/p' | while read -r b; do
      [ $((16#$b >> 16)) -ne 0 ] && echo x
    done | wc -l
}

failed=0
printf '%-4s %-10s %6s %7s %7s %7s %7s %7s %8s %6s %8s\n' job state time_s placed in_slot torque \
  overrun deadln link other late_per
for i in $(seq 1 "$jobs"); do
  "$cellctl" world reset >/dev/null || { echo "table_soak: world reset failed" >&2; failed=1; break; }
  t0=$SECONDS
  id="soak-$i-$$"
  "$cellctl" submit "$job_file" --id "$id" --wait --wait-s 600 >"$run_dir/job-$i.log" 2>&1
  rc=$?
  t=$((SECONDS - t0))
  summary="$("$cellctl" --json job "$id" 2>/dev/null || echo '{}')"
  state="$(jq -r '.state // "?"' <<<"$summary")"
  placed="$(jq -r '.parts_done // 0' <<<"$summary")"
  # Ground truth: parts on the table within 2 mm of a slot of the job's grid (the world's x, y
  # are the 7545's base frame's in the shipped scenes), one part per slot.
  in_slot="$("$cellctl" --json world parts 2>/dev/null | python3 -c '
import json, sys, yaml
place = yaml.safe_load(open(sys.argv[1]))["place"]
o = place["origin_mm"]
slots = [(o[0] + c * place["pitch_x_mm"], o[1] + r * place["pitch_y_mm"])
         for r in range(place["rows"]) for c in range(place["columns"])]
used = set()
doc = json.load(sys.stdin)
for part in doc.get("parts", []) if isinstance(doc, dict) else doc:
    pose = part.get("pose")
    if not pose or part.get("support") != "table":
        continue
    for i, (x, y) in enumerate(slots):
        if i not in used and abs(pose["x_mm"] - x) < 2 and abs(pose["y_mm"] - y) < 2:
            used.add(i)
            break
print(len(used))' "$job_file" 2>/dev/null || echo "?")"
  torque=$(board_faults 0x0F00)
  overrun=$(board_faults 0x00FF)
  deadline=$(board_faults 0x3000)
  link=$(count "$logs/gateway.ibm7545.log" 'link to the controller failed')
  other=$(gateway_faults)
  late="$("$cellctl" --json robot state --robot ibm7545 2>/dev/null | jq -r '.board.late_periods // "?"')"
  printf '%-4s %-10s %6d %7s %7s %7s %7s %7s %8s %6s %8s\n' "$i" "$state" "$t" "$placed" \
    "$in_slot" "$torque" "$overrun" "$deadline" "$link" "$other" "$late"
  if [ "$rc" -ne 0 ] || [ "$state" != succeeded ]; then
    failed=1
    # A job that did not end (paused on a fault): reset the robot so the next can run.
    "$cellctl" cancel "$id" >/dev/null 2>&1 || true
    "$cellctl" robot reset --robot ibm7545 >/dev/null 2>&1 || true
  fi
done
behind="$(grep -o 'board_clock_behind_s=[0-9.]*' "$logs/sim-7545.log" 2>/dev/null | tail -1 | cut -d= -f2)"
echo "table_soak: totals (cumulative over the run): torque $(board_faults 0x0F00), overrun" \
  "$(board_faults 0x00FF), deadline $(board_faults 0x3000), link" \
  "$(count "$logs/gateway.ibm7545.log" 'link to the controller failed'), other" \
  "$(gateway_faults); the board's clock" \
  "${behind:-0} s behind the host's" >&2
[ "$(board_faults 0x3FFF)" -eq 0 ] && [ "$(gateway_faults)" -eq 0 ] &&
  [ "$(count "$logs/gateway.ibm7545.log" 'link to the controller failed')" -eq 0 ] || failed=1
# The servo's own account over the whole run (the gateway logs it every 30 s and when it
# stops): following error |reference - encoder| p50 / p99 / max and the torque word's peak as
# a fraction of its range, per joint J1 J2 Z R (services/gateway/src/dpr7545_driver.hpp).
stop
trap - EXIT
line="$(grep 'msg="servo statistics"' "$logs/gateway.ibm7545.log" 2>/dev/null | tail -1)"
if [ -n "$line" ]; then
  field() { grep -oE " $1=(\"[^\"]*\"|[^ ]*)" <<<"$line" | cut -d= -f2 | tr -d '"'; }
  echo "table_soak: servo over $(field exchanges) exchanges (J1 J2 Z R): following error p50" \
    "$(field error_p50_counts) / p99 $(field error_p99_counts) / max $(field error_max_counts)" \
    "counts; torque word peak $(field torque_peak_fraction) of its range; setpoint steps" \
    "absorbed $(field setpoint_steps_absorbed); periods the simulator stalled (waited out," \
    "the arm still) $(field simulator_stall_cycles)" >&2
fi
exit "$failed"
