#!/usr/bin/env bash
# Configures and builds ptmkit. Usage: scripts/build.sh [--sanitize] [BUILD_DIR]
# Default build dir: build/release (build/asan with --sanitize).
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
sanitize=OFF
build=""
for a in "$@"; do
  case "$a" in
    --sanitize) sanitize=ON ;;
    *) build="$a" ;;
  esac
done
if [ -z "$build" ]; then
  if [ "$sanitize" = ON ]; then build="$root/build/asan"; else build="$root/build/release"; fi
fi
bash "$root/scripts/install-deps.sh"
btype=Release
bench=ON
extra=()
if [ "$sanitize" = ON ]; then
  # The sanitizer build is clang's and also builds the libFuzzer targets (the parsers'
  # code instrumented for coverage): scripts/fuzz.sh then runs them from this folder without a
  # build of its own.
  btype=RelWithDebInfo
  bench=OFF
  extra=(-DPTMKIT_FUZZ=ON)
  export CC="${CC:-clang}" CXX="${CXX:-clang++}"
fi
# Build output goes to stderr: stdout's last line is the build folder, for the callers.
cmake -S "$root" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE="$btype" -DPTMKIT_SANITIZE="$sanitize" \
  -DPTMKIT_BUILD_BENCH="$bench" "${extra[@]}" >&2
cmake --build "$build" -j "$(nproc)" >&2
echo "$build"
