#!/usr/bin/env bash
# The test command: installs what is missing (Debian packages), builds, and runs the whole
# suite with ctest. Usage: scripts/test.sh [ctest args, e.g. -R bus -L integration]
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
"$root/scripts/install-deps.sh"
"$root/scripts/build.sh"
build="${CELL_BUILD_DIR:-$root/build}"
# Tests isolate themselves (private domain ids, per-process partitions, loopback-only DDS).
# Four slots per core: most of the suite waits on real time (robots moving, services timing
# out); each test holds the slots its measured CPU needs, and the ones that time a robot against
# real time run alone (cmake/CellTargets.cmake, cell_add_test).
ctest --test-dir "$build" --output-on-failure -j "$((4 * $(nproc)))" --timeout 600 "$@"
