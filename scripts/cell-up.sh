#!/usr/bin/env bash
# The run command: installs what is missing, builds, and starts the whole simulated cell on
# this machine (every service and simulator of deploy/local.yaml) in the foreground.
# Ctrl-C (or `build/bin/cell down` from another terminal) stops it.
# Usage: scripts/cell-up.sh [cell up args, e.g. --profile deploy/local.yaml --detach]
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
"$root/scripts/install-deps.sh"
"$root/scripts/build.sh"
build="${CELL_BUILD_DIR:-$root/build}"
export CELL_HOME="$root"
exec "$build/bin/cell" up "$@"
