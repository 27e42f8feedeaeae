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
  liborocos-kdl-dev
  valgrind procps iproute2 openssl
)

missing=()
for p in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed'; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  exit 0
fi

echo "install-deps: installing ${#missing[@]} package(s): ${missing[*]}" >&2
SUDO=""
if [ "$(id -u)" -ne 0 ]; then
  SUDO="sudo"
fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
