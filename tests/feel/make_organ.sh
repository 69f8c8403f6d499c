#!/bin/sh
# The organ of the feel's reference traces (docs/tools.md, "The feel under
# regression tests"): palpate's sample organ as `palpate-precompute
# make-sample` makes it without --size (12 mm tetrahedra, 327 compliance
# vertices), with the demo's job (config/sample-organ.toml: E = 85 kPa,
# ν = 0.45, the stiffer tumour, the attachment sphere), by condensation.
# About 3 s; kept when it already holds this problem (--reuse).
#
# Usage: make_organ.sh PALPATE-PRECOMPUTE SOURCE_DIR OUT_DIR  (writes OUT_DIR/organ.h5)
set -eu
precompute=$1 source_dir=$2 out=$3
mkdir -p "$out"
"$precompute" -q make-sample -o "$out/organ.msh"
"$precompute" -q -j "$source_dir/config/sample-organ.toml" --mesh "$out/organ.msh" \
  --method condensation --no-xdmf --reuse -o "$out/organ.h5"
