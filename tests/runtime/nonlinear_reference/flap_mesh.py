#!/usr/bin/python3
"""The flap of issue 18 as a tetrahedral mesh, and its palpate-precompute job.

The flap is the box x in [0, L], y in [-W/2, W/2], z in [0, T] (metres;
L = 0.1, W = 0.04, T = 0.01 by default), fixed at x = 0. It is cut into
structured hexahedra of about `spacing` metres (each axis gets
round(extent / spacing) cells, at least one), and each hexahedron into six
tetrahedra by the Kuhn (Freudenthal) split: for each ordering (p, q, r) of
the three axes, the tetrahedron with vertices c, c + e_p, c + e_p + e_q,
c + e_p + e_q + e_r (c the cell's lowest corner, e the cell's edge vectors).
All cells use the same split, so the faces of neighbouring cells are cut
along the same diagonal: the mesh is conforming. Each tetrahedron is listed
positively oriented ((P1-P0).((P2-P0)x(P3-P0)) > 0). Cells with y < 0 use
the split mirrored in y, so the mesh is symmetric about y = 0 when the width
has an even number of cells.

The default spacing is T / 3 = 3.33 mm (3 elements through the thickness,
30 x 12 x 3 cells, 1,612 vertices, 6,480 tetrahedra).

Usage:
    flap_mesh.py OUTDIR [--spacing S] [--length L --width W --thickness T]
writes OUTDIR/flap.msh (Gmsh MSH 2.2 ASCII) and OUTDIR/flap.toml (E = 20 kPa,
nu = 0.45, mesh unit m, the vertices at x = 0 fixed by a box), for
    palpate-precompute -j OUTDIR/flap.toml -o OUTDIR/flap.h5 --method solves
"""

import argparse
import itertools
import os
import sys

import numpy as np

YOUNG_MODULUS_PA = 20e3
POISSON_RATIO = 0.45


def flap_mesh(length=0.1, width=0.04, thickness=0.01, spacing=None):
    """Return (vertices [V,3] m, tetrahedra [T,4] 0-based, positively oriented)."""
    if spacing is None:
        spacing = thickness / 3.0
    if not (spacing > 0):
        raise ValueError(f"spacing must be > 0 m, got {spacing}")
    counts = [max(1, int(round(e / spacing))) for e in (length, width, thickness)]
    nx, ny, nz = counts
    xs = np.linspace(0.0, length, nx + 1)
    ys = np.linspace(-width / 2, width / 2, ny + 1)
    zs = np.linspace(0.0, thickness, nz + 1)
    # Vertex (i, j, k) has index (i * (ny + 1) + j) * (nz + 1) + k.
    grid = np.stack(np.meshgrid(xs, ys, zs, indexing="ij"), axis=-1)
    vertices = grid.reshape(-1, 3)

    def index(i, j, k):
        return (i * (ny + 1) + j) * (nz + 1) + k

    ci, cj, ck = np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij")
    ci, cj, ck = ci.ravel(), cj.ravel(), ck.ravel()
    # Cells with y < 0 use the split mirrored in y (offset o_y -> 1 - o_y), so the
    # mesh is symmetric about y = 0 (no spurious sideways force). Still conforming:
    # a mirrored and a plain cell share only faces y = const, whose diagonal
    # joins the (x, z) corners (0, 0) and (1, 1) in both splits.
    mirrored = (2 * cj + 1) < ny
    tets = []
    for order in itertools.permutations(range(3)):
        corner = np.zeros(3, dtype=int)
        path = [corner.copy()]
        for axis in order:
            corner[axis] += 1
            path.append(corner.copy())
        oy = [np.where(mirrored, 1 - o[1], o[1]) for o in path]
        tets.append(np.stack([index(ci + o[0], cj + y, ck + o[2]) for o, y in zip(path, oy)], axis=1))
    tets = np.concatenate(tets, axis=0)
    p = vertices[tets]
    vol6 = np.einsum("ij,ij->i", p[:, 1] - p[:, 0], np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]))
    negative = vol6 < 0
    tets[negative] = tets[negative][:, [0, 2, 1, 3]]
    return vertices, tets


def write_msh2(path, vertices, tets):
    """Gmsh MSH 2.2 ASCII: 1-based node tags, element type 4 (4-node tetrahedron)."""
    with open(path, "w") as f:
        f.write("$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n")
        f.write(f"{len(vertices)}\n")
        for i, v in enumerate(vertices):
            f.write(f"{i + 1} {v[0]:.17g} {v[1]:.17g} {v[2]:.17g}\n")
        f.write("$EndNodes\n$Elements\n")
        f.write(f"{len(tets)}\n")
        for e, t in enumerate(tets):
            f.write(f"{e + 1} 4 2 1 1 {t[0] + 1} {t[1] + 1} {t[2] + 1} {t[3] + 1}\n")
        f.write("$EndElements\n")


def read_msh2(path):
    """Read back an MSH 2.2 ASCII file with only 4-node tetrahedra (other elements skipped)."""
    with open(path) as f:
        lines = [line.strip() for line in f.read().split("\n")]
    try:
        version, binary = lines[lines.index("$MeshFormat") + 1].split()[:2]
    except (ValueError, IndexError):
        raise ValueError(f"{path}: no $MeshFormat section; accepted: Gmsh MSH 2.2 ASCII")
    if not version.startswith("2") or binary != "0":
        raise ValueError(f"{path}: MSH version {version}{' binary' if binary != '0' else ''}; accepted: MSH 2.2 ASCII")
    i = lines.index("$Nodes")
    n = int(lines[i + 1])
    tags, coords = [], []
    for line in lines[i + 2 : i + 2 + n]:
        parts = line.split()
        tags.append(int(parts[0]))
        coords.append([float(x) for x in parts[1:4]])
    rank = {t: r for r, t in enumerate(tags)}
    i = lines.index("$Elements")
    m = int(lines[i + 1])
    tets = []
    for line in lines[i + 2 : i + 2 + m]:
        parts = [int(x) for x in line.split()]
        if parts[1] != 4:
            continue
        ntags = parts[2]
        tets.append([rank[t] for t in parts[3 + ntags : 7 + ntags]])
    if not tets:
        raise ValueError(f"{path}: no 4-node tetrahedron (element type 4)")
    return np.array(coords), np.array(tets, dtype=np.int64)


def write_job(path, mesh_name, length):
    """palpate-precompute job: E, nu, unit m, the vertices at x = 0 fixed."""
    tol = 1e-6 * length
    with open(path, "w") as f:
        f.write(
            "# The flap of issue 18 (tests/runtime/nonlinear_reference/flap_mesh.py).\n"
            f'[mesh]\nfile = "{mesh_name}"\nunit = "m"\n\n'
            f"[material]\nyoung_modulus_pa = {YOUNG_MODULUS_PA!r}\npoisson_ratio = {POISSON_RATIO!r}\n\n"
            "[attachment]\n# the vertices at x = 0\n"
            f"boxes = [ {{ min = [{-tol!r}, -1.0, -1.0], max = [{tol!r}, 1.0, 1.0] }} ]\n\n"
            '[compute]\nmethod = "solves"\n\n[output]\nxdmf = false\n'
        )


def main(argv):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("outdir")
    ap.add_argument("--spacing", type=float, default=None, help="cell size, m (default thickness/3)")
    ap.add_argument("--length", type=float, default=0.1)
    ap.add_argument("--width", type=float, default=0.04)
    ap.add_argument("--thickness", type=float, default=0.01)
    ap.add_argument("--name", default="flap")
    a = ap.parse_args(argv)
    os.makedirs(a.outdir, exist_ok=True)
    v, t = flap_mesh(a.length, a.width, a.thickness, a.spacing)
    msh = os.path.join(a.outdir, a.name + ".msh")
    write_msh2(msh, v, t)
    write_job(os.path.join(a.outdir, a.name + ".toml"), a.name + ".msh", a.length)
    print(f"{msh}: {len(v)} vertices, {len(t)} tetrahedra")


if __name__ == "__main__":
    main(sys.argv[1:])
