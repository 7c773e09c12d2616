#!/usr/bin/env bash
# Builds the libFuzzer targets (fuzz/, clang, ASan + UBSan) and runs each for a bounded time.
# Usage: scripts/fuzz.sh [SECONDS_PER_TARGET] [BUILD_DIR]     (default 20 s, build/fuzz)
# BUILD_DIR may be the sanitizer build of scripts/test.sh --sanitize (build/asan), which has
# the targets already; otherwise one is configured with clang and only the targets are built.
# Corpus: fuzz/seeds/TARGET (committed) plus BUILD_DIR/corpus/TARGET (what runs found; kept
# between runs, not committed). A finding (crash, sanitizer report, leak, uncaught exception
# other than ptmkit::Error, timeout, allocation past the limits) is saved under
# BUILD_DIR/findings/ and makes the script fail. Prints one line per target: executions,
# corpus size, findings.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
seconds="${1:-20}"
build="${2:-$root/build/fuzz}"
targets=(lp ptm rti json image web)
bash "$root/scripts/install-deps.sh"
if ! grep -q '^PTMKIT_FUZZ:BOOL=ON' "$build/CMakeCache.txt" 2>/dev/null; then
  CC=clang CXX=clang++ cmake -S "$root" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DPTMKIT_FUZZ=ON -DPTMKIT_BUILD_TESTS=OFF >&2
fi
cmake --build "$build" -j "$(nproc)" --target "${targets[@]/#/fuzz_}" >&2
asan="${ASAN_OPTIONS:-detect_leaks=1:abort_on_error=1}"
export LSAN_OPTIONS="${LSAN_OPTIONS:-suppressions=$root/scripts/lsan.supp:print_suppressions=0}"
export UBSAN_OPTIONS="${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}"
mkdir -p "$build/findings"
failed=0
total=0
for target in "${targets[@]}"; do
  corpus="$build/corpus/$target"
  mkdir -p "$corpus"
  log="$build/fuzz_$target.log"
  # One worker: the machine's other core stays free; -rss_limit_mb and -malloc_limit_mb make
  # an allocation the input declares but the reader should have refused a finding.
  # The image target unwinds fully on malloc: a leak inside OpenImageIO (its PNG reader leaks a
  # string when libpng bails out of a damaged file) then shows the library frame that
  # scripts/lsan.supp names. Slower, so only there.
  export ASAN_OPTIONS="$asan"
  [ "$target" = image ] && export ASAN_OPTIONS="$asan:fast_unwind_on_malloc=0"
  set +e
  "$build/fuzz/fuzz_$target" "$corpus" "$root/fuzz/seeds/$target" \
    -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 -malloc_limit_mb=2048 \
    -print_final_stats=1 -artifact_prefix="$build/findings/$target-" >"$log" 2>&1
  rc=$?
  set -e
  # libFuzzer prints its final stats twice when a finding stops it: the last count is taken.
  runs="$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$' | tail -n 1)"
  runs="${runs:-0}"
  found="$(ls "$build/findings" | grep -c "^$target-" || true)"
  total=$((total + runs))
  echo "fuzz_$target: $runs executions in ${seconds} s, corpus $(ls "$corpus" | wc -l) files, findings $found (exit $rc)"
  if [ "$rc" -ne 0 ] || [ "$found" -ne 0 ]; then
    failed=1
    grep -E "ERROR|SUMMARY|==[0-9]+==|runtime error|terminate" "$log" | head -20 || true
  fi
done
echo "fuzz: $total executions in all"
exit "$failed"
