#!/usr/bin/env bash
# Installs the Debian packages cell needs, idempotently: when everything is present it
# only runs dpkg-query (well under a second) and touches nothing.
set -euo pipefail

PACKAGES=(
  build-essential cmake ninja-build pkg-config git
  cyclonedds-dev cyclonedds-tools libddsc0debian
  libeigen3-dev libopencv-dev libceres-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  libyaml-cpp-dev libspdlog-dev libfmt-dev libcli11-dev nlohmann-json3-dev
  liborocos-kdl-dev libsqlite3-dev
  valgrind procps iproute2 openssl nftables util-linux systemd jq
  libcpp-httplib-dev chromium
  clang-tidy python3 lld
)

missing=()
for p in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed'; then
    missing+=("$p")
  fi
done

# Node.js with npm for the web monitor's build (clients/monitor/web): Debian's, unless one is
# installed already (a NodeSource nodejs carries its own npm and conflicts with Debian's).
if ! command -v npm >/dev/null 2>&1; then
  missing+=(nodejs npm)
fi

if [ ${#missing[@]} -gt 0 ]; then
  echo "install-deps: installing ${#missing[@]} package(s): ${missing[*]}" >&2
  SUDO=""
  if [ "$(id -u)" -ne 0 ]; then
    SUDO="sudo"
  fi
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi

# The web monitor's npm packages (three, esbuild, playwright-core) from its package-lock.json,
# only when node_modules is missing or older than the lock file (a no-op otherwise).
web="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)/clients/monitor/web"
if [ -f "$web/package-lock.json" ] &&
   { [ ! -d "$web/node_modules" ] || [ "$web/package-lock.json" -nt "$web/node_modules" ]; }; then
  echo "install-deps: npm ci in clients/monitor/web" >&2
  (cd "$web" && npm ci --no-audit --no-fund --loglevel=error)
  touch "$web/node_modules"
fi
