#!/usr/bin/env bash
# The tutorial's first step (docs/tutorial-stl-to-haptics.md): its Gmsh
# script config/tutorial/liver-from-stl.geo fills a closed STL surface with
# tetrahedra of the size asked, and palpate-precompute takes the result.
# The surface: an ellipsoid of semi-axes 60 × 40 × 30 mm made by Gmsh.
#
# Usage: tests/scripts/tutorial_geo_test.sh PALPATE_PRECOMPUTE
set -euo pipefail
precompute=$1
source_dir=$(realpath "$(dirname "$0")/../..")
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
fail() { echo "tutorial_geo: $*" >&2; exit 1; }

printf 'SetFactory("OpenCASCADE");\nSphere(1) = {0, 0, 0, 1};\nDilate {{0, 0, 0}, {60, 40, 30}} { Volume{1}; }\nMesh.MeshSizeMax = 4;\n' \
  > "$work/ellipsoid.geo"
gmsh -2 "$work/ellipsoid.geo" -format stl -o "$work/organ.stl" >"$work/gmsh-stl.log" 2>&1 ||
  fail "gmsh could not make the test surface: $(tail -3 "$work/gmsh-stl.log")"
# Gmsh writes the output even when meshing fails: its exit code decides.
gmsh -3 "$source_dir/config/tutorial/liver-from-stl.geo" -setstring stl "$work/organ.stl" \
  -setnumber size 10 -o "$work/organ.msh" >"$work/gmsh.log" 2>&1 ||
  fail "the tutorial's .geo failed: $(tail -3 "$work/gmsh.log")"
"$precompute" --mesh "$work/organ.msh" --mesh-unit mm -E 85e3 --nu 0.45 \
  --fix-half-space 0 0 20 0 0 1 --method condensation -o "$work/organ.h5" -q ||
  fail "palpate-precompute refused the tutorial's mesh"

/usr/bin/python3 - "$work/organ.h5" <<'PY'
import math, sys
import h5py, numpy as np
with h5py.File(sys.argv[1], "r") as f:
    v, t = f["/mesh/vertices"][:], f["/mesh/tetrahedra"][:]
a, b, c, d = (v[t[:, i]] for i in range(4))
volume = np.einsum("ij,ij->i", b - a, np.cross(c - a, d - a)).sum() / 6
ellipsoid = 4 / 3 * math.pi * 0.060 * 0.040 * 0.030
ratio = volume / ellipsoid
print(f"tutorial_geo: {len(v)} vertices, {len(t)} tetrahedra, volume {ratio:.4f} of the ellipsoid's")
failures = []
# Inscribed in the faceted surface: a little less than the ellipsoid, never more.
if not 0.95 < ratio <= 1.0:
    failures.append(f"volume ratio {ratio:.4f}, expected in (0.95, 1.0]")
# Size 10 mm on this ellipsoid gives about 600 vertices; elements several
# times smaller (the 40-degree patch problem the .geo avoids) would give thousands.
if not 200 <= len(v) <= 2000:
    failures.append(f"{len(v)} vertices, expected 200 to 2000 at size 10 mm")
if failures:
    sys.exit("tutorial_geo: " + "; ".join(failures))
PY
