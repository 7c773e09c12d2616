#!/usr/bin/env bash
# Whole-fit benchmark: a generated 49-image, 12-megapixel JPEG stack (rendered once by
# `ptmkit synth`), decode-only time through the same reader (at its fastest band size), then
# `ptmkit fit` (LRGB and RGB; to a new file and over an existing one), interleaved, medians of
# RUNS runs, with peak resident memory.
# Figures go in docs/PERFORMANCE.md.
# Usage: [RUNS=N] [SETTLE=S] [NOISE=SIGMA] scripts/bench-fit.sh [WORK_DIR] [THREADS]
#   (default: /tmp/ptmkit-bench, 2 threads, 3 runs, sensor noise 3 grey levels)
# PTMKIT_BUILD=DIR uses an existing build instead of building build/release.
# PTMKIT_BASELINE=DIR also runs another build's ptmkit (DIR/apps/ptmkit, e.g. an earlier
# version) in every round, to a new file, and prints its medians, this build's time as a
# fraction of its, and whether the two wrote the same bytes.
# NOISE is the rendered sensor noise (sigma, grey levels). Decoding cost follows the JPEGs'
# size: at 3 they are 1.9 bits a pixel, at 1 (the synthetic preset's own) 0.9, against 2.3
# for the real photographs in ../shared/data; and a real quality-95 stack of this size
# decodes slower than the NOISE=3 one (docs/PERFORMANCE.md). NOISE=1 gives a decode floor
# far cheaper than a real capture's.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
work="${1:-/tmp/ptmkit-bench}"
threads="${2:-2}"
build="${PTMKIT_BUILD:-$(bash "$root/scripts/build.sh" | tail -n 1)}"
ptmkit="$build/apps/ptmkit"
noise="${NOISE:-3}"
stack="$work/s12mp-noise$noise"
mkdir -p "$work"
if [ ! -f "$stack/lights.lp" ]; then
  echo "== rendering 49 x 4000x3000 JPEG (quality 95, noise $noise) into $stack"
  "$ptmkit" synth --out "$stack" --width 4000 --height 3000 --format jpg --no-shadows \
    --no-truth --lights dome49 --seed 3 --noise "$noise"
fi

# The commands run interleaved, in rounds (decode; lrgb new, lrgb replacing; rgb new, rgb
# replacing), RUNS rounds (default 3): on a
# shared machine, whose speed drifts, interleaving keeps the ratios fair. Each fit runs twice:
# first to a new output file (the outputs of the round before are removed when a round starts,
# as for a first fit of a capture), then again over that file (replacing an existing output:
# the file system then also frees the old file, and ext4 starts writing the new one back when
# it is renamed over the old). Every command starts after `sync`, so that no command's timing
# includes the write-back of an earlier one's output, and after SETTLE seconds of idle (0
# unless set; on a virtual machine the host may still be busy with what the guest wrote).
# Each figure is the median wall time (with the range), and the peak resident memory over the
# runs.
runs="${RUNS:-3}"
settle="${SETTLE:-0}"
kinds="floor decode lrgb rgb lrgb-replace rgb-replace base-lrgb base-rgb"
baseline="${PTMKIT_BASELINE:-}"
for kind in $kinds; do rm -f "$work/$kind.times"; done
run_once() {  # run_once TIMES_FILE COMMAND...: appends "wall_s max_rss_kib"
  local out="$1"
  shift
  sync
  sleep "$settle"
  /usr/bin/time -f "%e %M" -o "$work/time.txt" "$@" >/dev/null
  cat "$work/time.txt" >>"$out"
}
# Prints "median_wall_s min max peak_rss_mib" of a times file.
summary() {
  sort -n "$1" | awk '{w[NR] = $1; if ($2 > m) m = $2}
    END {printf "%s %s %s %d\n", w[int((NR + 1) / 2)], w[1], w[NR], m / 1024}'
}

pixels=$((4000 * 3000))
decoded_mib=$((49 * pixels * 3 / 1024 / 1024))
jpeg_bytes=$(cat "$stack"/*.jpg | wc -c)
bits_per_px=$(awk "BEGIN{printf \"%.2f\", $jpeg_bytes * 8 / (49 * $pixels)}")
echo "stack: $stack: 49 images, 4000x3000x3 (JPEG $bits_per_px bits a pixel), decoded size (8-bit) $decoded_mib MiB; threads $threads; runs $runs; settle $settle s"
for _ in $(seq "$runs"); do
  rm -f "$work/out-lrgb.ptm" "$work/out-rgb.ptm"
  run_once "$work/floor.times" "$build/bench/jpeg_floor" "$stack/lights.lp" "$threads"
  run_once "$work/decode.times" "$build/bench/decode_stack" "$stack/lights.lp" "$threads"
  for fmt in lrgb rgb; do
    for kind in "$fmt" "$fmt-replace"; do
      run_once "$work/$kind.times" "$ptmkit" fit "$stack/lights.lp" -o "$work/out-$fmt.ptm" \
        --format "$fmt" --threads "$threads"
    done
    if [ -n "$baseline" ]; then
      rm -f "$work/base-$fmt.ptm"
      run_once "$work/base-$fmt.times" "$baseline/apps/ptmkit" fit "$stack/lights.lp" \
        -o "$work/base-$fmt.ptm" --format "$fmt" --threads "$threads"
    fi
  done
done
read -r floor_s floor_lo floor_hi floor_mib < <(summary "$work/floor.times")
echo "libjpeg alone (jpeg_floor)   : ${floor_s} s (${floor_lo}-${floor_hi}), peak ${floor_mib} MiB"
read -r dec_s dec_lo dec_hi dec_mib < <(summary "$work/decode.times")
dratio=$(awk "BEGIN{printf \"%.2f\", $dec_s/$floor_s}")
echo "decode only (StackReader)    : ${dec_s} s (${dec_lo}-${dec_hi}; ${dratio}x floor), peak ${dec_mib} MiB"
for kind in lrgb rgb lrgb-replace rgb-replace; do
  read -r fit_s fit_lo fit_hi fit_mib < <(summary "$work/$kind.times")
  ratio=$(awk "BEGIN{printf \"%.2f\", $fit_s/$dec_s}")
  fratio=$(awk "BEGIN{printf \"%.2f\", $fit_s/$floor_s}")
  frac=$(awk "BEGIN{printf \"%.3f\", $fit_mib/$decoded_mib}")
  what="new file"
  case "$kind" in *-replace) what="over the last" ;; esac
  printf 'ptmkit fit --format %-4s (%s): %s s (%s-%s; %sx decode, %sx floor), peak %s MiB (%s of decoded stack)\n' \
    "${kind%-replace}" "$what" "$fit_s" "$fit_lo" "$fit_hi" "$ratio" "$fratio" "$fit_mib" "$frac"
done
if [ -n "$baseline" ]; then
  for fmt in lrgb rgb; do
    read -r fit_s _ _ _ < <(summary "$work/$fmt.times")
    read -r base_s base_lo base_hi base_mib < <(summary "$work/base-$fmt.times")
    same="different bytes"
    cmp -s "$work/out-$fmt.ptm" "$work/base-$fmt.ptm" && same="the same bytes"
    printf 'baseline fit --format %-4s (new file): %s s (%s-%s), peak %s MiB; this build %s of it; %s\n' \
      "$fmt" "$base_s" "$base_lo" "$base_hi" "$base_mib" \
      "$(awk "BEGIN{printf \"%.2fx\", $fit_s/$base_s}")" "$same"
  done
fi
