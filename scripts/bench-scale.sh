#!/usr/bin/env bash
# Scale benchmarks (docs/SCALE.md, docs/PERFORMANCE.md):
#   ranks  - one 49 x 4000x3000 JPEG capture fitted by 1-4 MPI processes (oversubscribed on a
#            small machine; --bind-to none, since Open MPI binds each process to one core by
#            default for 2 processes or fewer), LRGB: wall time, speed-up against one plain
#            process, each process's peak memory, and the output compared byte for byte with
#            the plain process's.
#   large  - a 49 x 16000x16000 (256-megapixel) JPEG capture fitted by one process, LRGB and
#            RGB: wall time and peak memory, beside libjpeg alone decoding the same files.
# Captures are rendered once by bench/make_large_stack (row by row, bounded memory).
# Usage: scripts/bench-scale.sh ranks|large|all [WORK_DIR]   (default /tmp/ptmkit-scale)
# PTMKIT_BUILD=DIR uses an existing build instead of building build/release.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
what="${1:-all}"
work="${2:-/tmp/ptmkit-scale}"
build="${PTMKIT_BUILD:-$(bash "$root/scripts/build.sh" | tail -n 1)}"
ptmkit="$build/apps/ptmkit"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
mkdir -p "$work"
if [ ! -f "$work/dome49/lights.lp" ]; then
  "$ptmkit" synth --out "$work/dome49" --size 8 --lights dome49 --no-truth >/dev/null
fi

render() {  # DIR WIDTH HEIGHT
  if [ ! -f "$1/lights.lp" ]; then
    mkdir -p "$1"
    echo "== rendering 49 x $2x$3 JPEG (quality 95) into $1"
    /usr/bin/time -f "   %e s, peak %M KiB" "$build/bench/make_large_stack" "$1" "$2" "$3" \
      "$work/dome49/lights.lp" 95 2
  fi
}

# Runs a command after `sync`; prints "SECONDS PEAK_KIB" (peak over the processes it
# started when they are wrapped by /usr/bin/time each).
timed() {
  sync
  local t0 t1
  t0=$(date +%s.%N)
  "$@" >/dev/null 2>"$work/last.err" || { cat "$work/last.err"; return 1; }
  t1=$(date +%s.%N)
  local peak
  peak=$(grep -o 'PEAK [0-9]*' "$work/last.err" | awk '{print $2}' | sort -n | tail -1)
  echo "$(awk -v a="$t0" -v b="$t1" 'BEGIN { printf "%.3f", b - a }') ${peak:-0}"
}

if [ "$what" = ranks ] || [ "$what" = all ]; then
  cap="$work/s12mp"
  render "$cap" 4000 3000
  echo "== ranks: 49 x 4000x3000, LRGB, $(nproc) cores"
  printf "%-10s %-9s %9s %9s %15s  %s\n" processes threads seconds speed-up "peak/process" output
  # One plain process (no launcher), all cores: the reference for time and bytes.
  r=$(timed /usr/bin/time -f "PEAK %M" "$ptmkit" fit "$cap/lights.lp" -o "$work/ranks-ref.ptm" \
    --format lrgb)
  base=${r% *}
  printf "%-10s %-9s %9.2f %9.2f %12d MiB  %s\n" "plain" all "$base" 1 "$((${r#* } / 1024))" reference
  for threads in 0 1; do
    for n in 1 2 3 4; do
      out="$work/ranks-$n.ptm"
      r=$(timed mpirun -np "$n" --oversubscribe --bind-to none /usr/bin/time -f "PEAK %M" \
        "$ptmkit" fit "$cap/lights.lp" -o "$out" --format lrgb --threads "$threads")
      s=${r% *}
      peak=${r#* }
      same=$(cmp -s "$out" "$work/ranks-ref.ptm" && echo identical || echo DIFFERS)
      printf "%-10s %-9s %9.2f %9.2f %12d MiB  %s\n" "$n" "$([ "$threads" = 0 ] && echo all || echo "$threads")" \
        "$s" "$(awk -v a="$base" -v b="$s" 'BEGIN { printf "%.3f", a / b }')" "$((peak / 1024))" "$same"
    done
  done
  rm -f "$work"/ranks-*.ptm
fi

if [ "$what" = large ] || [ "$what" = all ]; then
  cap="$work/s256mp"
  render "$cap" 16000 16000
  echo "== large: 49 x 16000x16000 ($(du -sh "$cap" | cut -f1) of JPEG), 2 threads"
  printf "%-34s %9s %14s\n" command seconds peak
  r=$(timed /usr/bin/time -f "PEAK %M" "$build/bench/jpeg_floor" "$cap/lights.lp" 2)
  printf "%-34s %9.1f %10d MiB\n" "jpeg_floor (libjpeg alone)" "${r% *}" "$((${r#* } / 1024))"
  for format in lrgb rgb; do
    r=$(timed /usr/bin/time -f "PEAK %M" "$ptmkit" fit "$cap/lights.lp" -o "$work/large.ptm" \
      --format "$format" --threads 2)
    printf "%-34s %9.1f %10d MiB\n" "ptmkit fit --format $format" "${r% *}" "$((${r#* } / 1024))"
    rm -f "$work/large.ptm"
  done
fi
