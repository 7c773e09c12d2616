#!/usr/bin/env bash
# Regenerates a fixed set of outputs with a given ptmkit binary and, given a reference folder
# made the same way by another binary, compares them byte for byte (cmp). It covers the
# commands whose outputs must not change when the code is restructured: synth presets, fits
# to .ptm in rgb, lrgb and ycc (8-bit and 16-bit input), robust solvers with every optional
# map, near lights (with and without fall-off), HSH bases, --model auto, and the SynthRTI set.
# Reports (JSON) hold timings and are not compared.
# Usage: scripts/check-identical.sh PTMKIT_BINARY OUT_DIR [REFERENCE_DIR]
#   e.g. scripts/check-identical.sh build/release/apps/ptmkit /tmp/ptmkit-new /tmp/ptmkit-ref
# Threads: THREADS (default 2); the outputs do not depend on it.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
bin="$(realpath "$1")"
out="$2"
ref="${3:-}"
threads="${THREADS:-2}"
data="${PTMKIT_DATA_DIR:-$root/../shared/data}"
[ -d "$data" ] || data="/work/shared/data"
rm -rf "$out"
mkdir -p "$out"
run() { "$bin" "$@" --threads "$threads" >/dev/null; }
fit() { run fit "$@"; }

# Captures.
run synth --out "$out/default" --preset default
run synth --out "$out/glossy" --preset glossy
run synth --out "$out/deep16" --preset default --size 96 --bits 16 --seed 5 --no-truth
run synth --out "$out/near" --preset default --size 128 --dome-radius 300 --mm-per-px 1 --seed 2

# Shared-matrix fits: bytes (rgb, lrgb), floats (ycc, 16-bit input), double precision.
d="$out/default/lights.lp"
fit "$d" -o "$out/def-rgb.ptm"
fit "$d" -o "$out/def-lrgb.ptm" --format lrgb
fit "$d" -o "$out/def-ycc.ptm" --format ycc
fit "$d" -o "$out/def-rgb-double.ptm" --precision double
fit "$d" -o "$out/def-ls-maps.ptm" --normals "$out/def-ls-normals.exr" \
  --albedo "$out/def-ls-albedo.exr" --residual-map "$out/def-ls-residual.exr"
fit "$out/deep16/lights.lp" -o "$out/deep16-rgb.ptm"
fit "$out/deep16/lights.lp" -o "$out/deep16-lrgb.ptm" --format lrgb
fit "$out/deep16/lights.lp" -o "$out/deep16-ycc.ptm" --format ycc

# Robust solvers with every optional map.
g="$out/glossy/lights.lp"
fit "$g" -o "$out/glossy-robust.ptm" --solver robust --normals "$out/glossy-robust-normals.png" \
  --albedo "$out/glossy-robust-albedo.png" --labels "$out/glossy-robust-labels" \
  --residual-map "$out/glossy-robust-residual.exr" --outlier-map "$out/glossy-robust-outliers.exr"
fit "$g" -o "$out/glossy-robust-lrgb.ptm" --solver robust --format lrgb
fit "$g" -o "$out/glossy-robust-ycc.ptm" --solver robust --format ycc
fit "$g" -o "$out/glossy-huber.ptm" --solver irls-huber

# Near lights.
n="$out/near"
fit "$n/lights.lp" -o "$out/near.ptm" --lights-json "$n/lights.json" --plane "$n/plane.json"
fit "$n/lights.lp" -o "$out/near-falloff-lrgb.ptm" --lights-json "$n/lights.json" \
  --plane "$n/plane.json" --falloff --format lrgb --normals "$out/near-normals.exr" \
  --albedo "$out/near-albedo.exr"

# HSH bases and model selection.
fit "$g" -o "$out/glossy-hsh2.rti" --model hsh2
fit "$g" -o "$out/glossy-hsh3.rti" --model hsh3
fit "$g" -o "$out/glossy-hsh3-lrgb.rti" --model hsh3 --format lrgb
fit "$g" -o "$out/glossy-hsh4.rti" --model hsh4
fit "$d" -o "$out/def-auto.rti" --model auto --format rgb
fit "$g" -o "$out/glossy-auto.rti" --model auto --format rgb

# The SynthRTI capture (skipped where the data are absent).
s="$data/synthrti-multi2-mat5/Dome/dirs.lp"
if [ -f "$s" ]; then
  fit "$s" -o "$out/synthrti-rgb.ptm"
  fit "$s" -o "$out/synthrti-lrgb.ptm" --format lrgb
  fit "$s" -o "$out/synthrti-hsh3.rti" --model hsh3
else
  echo "note: $s absent, SynthRTI outputs skipped" >&2
fi

if [ -z "$ref" ]; then
  echo "wrote $(find "$out" -type f | wc -l) files to $out"
  exit 0
fi
# Coefficient files and EXR maps must be the same bytes. Rendered PNGs (synth's photos and
# truth) must hold the same pixels: their encoding (compression, chunks) may change with the
# PNG writer, so where the bytes differ the pixels are compared (oiiotool --diff, exact).
status=0
count=0
pixels=0
while IFS= read -r f; do
  rel="${f#"$ref"/}"
  case "$rel" in *.json) continue ;; esac
  count=$((count + 1))
  if [ ! -f "$out/$rel" ]; then
    echo "missing: $rel"
    status=1
  elif ! cmp -s "$f" "$out/$rel"; then
    case "$rel" in
      *.png)
        if oiiotool --fail 0 --diff "$f" "$out/$rel" >/dev/null 2>&1; then
          pixels=$((pixels + 1))
        else
          echo "differs (pixels): $rel"
          status=1
        fi
        ;;
      *)
        echo "differs: $rel"
        status=1
        ;;
    esac
  fi
done < <(find "$ref" -type f | sort)
if [ "$status" = 0 ]; then
  echo "identical: $count files ($out against $ref): $((count - pixels)) byte for byte, $pixels PNGs pixel for pixel (encoded differently)"
else
  echo "NOT identical ($out against $ref)"
fi
exit "$status"
