#!/usr/bin/env bash
# Configures and builds cell in ./build (Ninja, warnings as errors). Idempotent: a second run
# only rebuilds what changed. Usage: scripts/build.sh [extra cmake args]
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="${CELL_BUILD_DIR:-$root/build}"
if [ ! -f "$build/build.ninja" ]; then
  cmake -S "$root" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCELL_WERROR=ON "$@"
fi
cmake --build "$build"
