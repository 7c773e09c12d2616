#!/usr/bin/env bash
# Whole-fit benchmark: a generated 49-image, 12-megapixel JPEG stack (rendered once by
# `ptmkit synth`), decode-only time through the same reader (at its fastest band size), then
# `ptmkit fit` (LRGB and RGB), each the median of 3 runs, with peak resident memory. Figures go
# in docs/PERFORMANCE.md.
# Usage: scripts/bench-fit.sh [WORK_DIR] [THREADS]   (default: /tmp/ptmkit-bench, 2 threads)
# PTMKIT_BUILD=DIR uses an existing build instead of building build/release.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
work="${1:-/tmp/ptmkit-bench}"
threads="${2:-2}"
build="${PTMKIT_BUILD:-$(bash "$root/scripts/build.sh" | tail -n 1)}"
ptmkit="$build/apps/ptmkit"
stack="$work/s12mp"
mkdir -p "$work"
if [ ! -f "$stack/lights.lp" ]; then
  echo "== rendering 49 x 4000x3000 JPEG (quality 95) into $stack"
  "$ptmkit" synth --out "$stack" --width 4000 --height 3000 --format jpg --no-shadows \
    --no-truth --lights dome49 --seed 3
fi

# Runs a command 3 times; prints "median_wall_s max_rss_mib".
measure() {
  local walls=() rss=0
  for _ in 1 2 3; do
    /usr/bin/time -f "%e %M" -o "$work/time.txt" "$@" >/dev/null
    read -r wall kib <"$work/time.txt"
    walls+=("$wall")
    [ "$kib" -gt "$rss" ] && rss=$kib
  done
  local median
  median=$(printf '%s\n' "${walls[@]}" | sort -n | sed -n 2p)
  echo "$median $((rss / 1024))"
}

pixels=$((4000 * 3000))
decoded_mib=$((49 * pixels * 3 / 1024 / 1024))
echo "stack: 49 images, 4000x3000x3, decoded size (8-bit) $decoded_mib MiB; threads $threads"
read -r dec_s dec_mib < <(measure "$build/bench/decode_stack" "$stack/lights.lp" "$threads")
echo "decode only          : ${dec_s} s, peak ${dec_mib} MiB"
for fmt in lrgb rgb; do
  read -r fit_s fit_mib < <(measure "$ptmkit" fit "$stack/lights.lp" -o "$work/out-$fmt.ptm" \
    --format "$fmt" --threads "$threads")
  ratio=$(awk "BEGIN{printf \"%.2f\", $fit_s/$dec_s}")
  frac=$(awk "BEGIN{printf \"%.3f\", $fit_mib/$decoded_mib}")
  echo "ptmkit fit --format $fmt : ${fit_s} s (${ratio}x decode), peak ${fit_mib} MiB (${frac} of decoded stack)"
done
