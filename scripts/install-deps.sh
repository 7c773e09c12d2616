#!/usr/bin/env bash
# Installs the Debian packages ptmkit builds against. Idempotent and quiet when all are present.
set -euo pipefail
packages=(
  build-essential cmake ninja-build pkg-config clang-format
  libeigen3-dev libceres-dev libopencv-dev libapriltag-dev
  libopenimageio-dev openimageio-tools libtbb-dev libjpeg-dev libpng-dev libtiff-dev
  libgtest-dev libgmock-dev libbenchmark-dev libcli11-dev nlohmann-json3-dev
  time clang libclang-rt-14-dev
  libcpp-httplib-dev libopenmpi-dev openmpi-bin
)
# The browser tests' chromium and node (scripts/install-browser-deps.sh; never fatal).
bash "$(dirname "$0")/install-browser-deps.sh" || true
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  exit 0
fi
echo "install-deps: installing ${missing[*]}"
SUDO=""
[ "$(id -u)" -eq 0 ] || SUDO=sudo
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
