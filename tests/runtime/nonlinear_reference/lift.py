#!/usr/bin/python3
"""Grasp a patch of an elastic body and lift it along a rotation: nonlinear and linear forces.

    lift.py --mesh MESH [--fix-box X0,Y0,Z0,X1,Y1,Z1] --grasp SPEC --angles 5,15,45
            [--axis-point PX,PY,PZ] [--axis-direction AX,AY,AZ] [--motion rigid|translate]
            [-E 20e3] [--nu 0.45] [--law neo-hookean|ccx|svk] [--compliance FILE.h5]

MESH is a Gmsh MSH 2.2 ASCII tetrahedral mesh in metres (flap_mesh.py writes
one; then --fix-box gives the fixed vertices) or a palpate compliance file
(.h5: its /mesh/vertices, /mesh/tetrahedra and /mesh/fixed_vertex_ids are
used, and by default its G for the linear answer and E, nu of material 0).

The grasp (which vertices are held by the tool), SPEC one of
  box:X0,Y0,Z0,X1,Y1,Z1     the vertices in the box (all of them, surface or not)
  surface-box:X0,...,Z1     the boundary vertices in the box
  sphere:CX,CY,CZ,R         the boundary vertices within R of C
  A+B                       the union of two (or more) of these
The motion of the grasped vertices at angle theta: the rotation by theta
about the axis through --axis-point along --axis-direction (right-handed):
  rigid      each grasped vertex p goes to a + R(theta) (p - a)
  translate  each goes by the same vector, the motion of the grasped
             vertices' centroid c: a + R(theta) (c - a) - c (no rotation)
The fixed vertices stay; every other vertex is free of force.

Numbers that start with "-" need the "=" form (--axis-point=-0.1,0,0).

Output on stdout: a line starting with "#" (mesh, grasp and law, time), then
CSV with a header, one row per angle: the summed force that the grasp
exerts on the body (N), nonlinear (law --law) and linear (W^-1 d from the
compliance file's G when there is one, W the grasped vertices' block; else
from this program's own small-strain stiffness), then the solver's
cumulative Newton iterations and seconds.
"""

import argparse
import math
import sys
import time

import numpy as np

import neo_hookean as nh
from flap_mesh import read_msh2


def rotation(axis, theta):
    """Right-handed rotation matrix by theta (rad) about the unit vector axis."""
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(theta) * k + (1 - math.cos(theta)) * (k @ k)


def select_grasp(spec, vertices, surface):
    """Vertex indices of the union of the regions of spec ("A+B+...")."""
    return np.unique(np.concatenate([_select_region(part, vertices, surface) for part in spec.split("+")]))


def _select_region(spec, vertices, surface):
    kind, _, numbers = spec.partition(":")
    try:
        v = [float(s) for s in numbers.split(",")]
    except ValueError:
        v = []
    if kind in ("box", "surface-box") and len(v) == 6:
        inside = np.all((vertices >= np.array(v[:3])) & (vertices <= np.array(v[3:])), axis=1)
        ids = np.nonzero(inside)[0]
        if kind == "surface-box":
            ids = np.intersect1d(ids, surface)
    elif kind == "sphere" and len(v) == 4:
        ids = np.intersect1d(np.nonzero(np.linalg.norm(vertices - np.array(v[:3]), axis=1) <= v[3])[0], surface)
    else:
        raise SystemExit(
            f"lift.py: bad --grasp {spec!r}; accepted: box:X0,Y0,Z0,X1,Y1,Z1, "
            "surface-box:X0,Y0,Z0,X1,Y1,Z1, sphere:CX,CY,CZ,R (metres)"
        )
    if len(ids) == 0:
        raise SystemExit(f"lift.py: --grasp region {spec!r} selects no vertex")
    return ids


def motion(kind, rest, axis_point, axis_direction):
    """target(theta) -> positions [n,3] of the grasped vertices with rest positions rest [n,3]."""
    a = np.asarray(axis_point, dtype=float)
    if kind == "rigid":
        return lambda th: a + (rest - a) @ rotation(axis_direction, th).T
    if kind == "translate":
        c = rest.mean(axis=0)
        return lambda th: rest + (a + rotation(axis_direction, th) @ (c - a) - c)
    raise SystemExit(f"lift.py: bad --motion {kind!r}; accepted: rigid, translate")


def linear_forces_from_compliance(h5path, grasped, displacements):
    """Summed force W^-1 d per displacement set, W = the grasped vertices' block of G."""
    import h5py

    with h5py.File(h5path, "r") as f:
        ids = f["/compliance/vertex_ids"][()]
        rank = {int(v): r for r, v in enumerate(ids)}
        missing = [int(v) for v in grasped if int(v) not in rank]
        if missing:
            raise SystemExit(f"lift.py: grasped vertices {missing[:5]} are not compliance vertices of {h5path}")
        r = np.array([rank[int(v)] for v in grasped])
        dofs = (3 * r[:, None] + np.arange(3)).ravel()
        # h5py reads increasing indices only: read sorted, then put back in grasp order.
        order = np.argsort(dofs)
        sub = f["/compliance/G"][dofs[order], :][:, dofs[order]]
        back = np.empty_like(order)
        back[order] = np.arange(len(order))
        W = sub[np.ix_(back, back)]
    W = 0.5 * (W + W.T)
    return [np.linalg.solve(W, d.ravel()).reshape(-1, 3).sum(axis=0) for d in displacements]


def check_same_mesh(h5path, vertices):
    """The compliance file's vertices must be the mesh's, in the same order (to 1e-9 m)."""
    import h5py

    with h5py.File(h5path, "r") as f:
        stored = f["/mesh/vertices"][()]
    if stored.shape != vertices.shape or np.max(np.abs(stored - vertices)) > 1e-9:
        raise ValueError(f"{h5path}: its /mesh/vertices are not the mesh's (same count and order, in metres, are needed)")


def load_mesh(path, fix_box):
    if path.endswith(".h5"):
        import h5py

        with h5py.File(path, "r") as f:
            X = f["/mesh/vertices"][()]
            T = f["/mesh/tetrahedra"][()].astype(np.int64)
            fixed = f["/mesh/fixed_vertex_ids"][()].astype(np.int64)
            E = float(f["/material/young_modulus_pa"][0])
            nu = float(f["/material/poisson_ratio"][0])
        return X, T, fixed, (E, nu)
    X, T = read_msh2(path)
    if fix_box is None:
        raise SystemExit("lift.py: a .msh mesh needs --fix-box")
    lo, hi = np.array(fix_box[:3]), np.array(fix_box[3:])
    fixed = np.nonzero(np.all((X >= lo) & (X <= hi), axis=1))[0]
    return X, T, fixed, None


def run(args):
    X, T, fixed, file_material = load_mesh(args.mesh, args.fix_box)
    E = args.E if args.E is not None else (file_material[0] if file_material else 20e3)
    nu = args.nu if args.nu is not None else (file_material[1] if file_material else 0.45)
    solid = nh.Solid(X, T, E, nu, args.law)
    surface = nh.boundary_vertices(T)
    grasped = np.setdiff1d(select_grasp(args.grasp, X, surface), fixed)
    if len(grasped) == 0:
        raise ValueError(f"--grasp {args.grasp!r} selects only fixed vertices")
    angles = [float(a) for a in args.angles.split(",")]
    target = motion(args.motion, X[grasped], args.axis_point, args.axis_direction)
    rad = [math.radians(a) for a in angles]
    displacements = [target(t) - X[grasped] for t in rad]
    compliance = args.compliance or (args.mesh if args.mesh.endswith(".h5") else None)
    if compliance:
        check_same_mesh(compliance, X)
        linear = linear_forces_from_compliance(compliance, grasped, displacements)
    else:
        linear = [nh.linear_reaction(solid, fixed, grasped, d) for d in displacements]
    log = (lambda s: print(s, file=sys.stderr)) if args.verbose else None
    t0 = time.perf_counter()
    results = nh.solve_path(solid, fixed, grasped, target, rad, max_step=math.radians(args.max_step), log=log)
    info = (
        f"# {len(X)} vertices, {len(T)} tetrahedra, {len(fixed)} fixed, {len(grasped)} grasped; "
        f"law {args.law}, E = {E:g} Pa, nu = {nu:g}; {time.perf_counter() - t0:.2f} s"
    )
    return info, angles, results, linear, grasped


def floats(n):
    def parse(text):
        try:
            v = [float(s) for s in text.split(",")]
        except ValueError:
            v = []
        if len(v) != n:
            raise argparse.ArgumentTypeError(f"expected {n} comma-separated numbers, got {text!r}")
        return v

    return parse


def main(argv):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--mesh", required=True)
    ap.add_argument("--fix-box", type=floats(6), help="X0,Y0,Z0,X1,Y1,Z1 (m): fix the vertices in this box")
    ap.add_argument("--grasp", required=True)
    ap.add_argument("--angles", required=True, help="degrees, comma-separated, increasing")
    ap.add_argument("--axis-point", type=floats(3), default=[0.0, 0.0, 0.005], help="PX,PY,PZ (m)")
    ap.add_argument("--axis-direction", type=floats(3), default=[0.0, -1.0, 0.0], help="AX,AY,AZ")
    ap.add_argument("--motion", default="rigid")
    ap.add_argument("-E", type=float, default=None)
    ap.add_argument("--nu", type=float, default=None)
    ap.add_argument("--law", default="neo-hookean", choices=nh.LAWS)
    ap.add_argument("--compliance", help="palpate compliance file for the linear answer")
    ap.add_argument("--max-step", type=float, default=15.0, help="largest angle increment, degrees (default 15)")
    ap.add_argument("-v", "--verbose", action="store_true")
    args = ap.parse_args(argv)
    try:
        angles = [float(x) for x in args.angles.split(",")]
    except ValueError:
        angles = []
    if not angles or not all(a < b for a, b in zip([0.0] + angles, angles)) or angles[-1] > 180:
        sys.exit(f"lift.py: bad --angles {args.angles!r}; accepted: increasing degrees in (0, 180], comma-separated")
    try:
        info, angles, results, linear, _ = run(args)
    except (OSError, ValueError, KeyError) as e:
        sys.exit(f"lift.py: {e}")
    except nh.NotConverged as e:
        sys.exit(f"lift.py: the nonlinear solve did not converge ({e}); try a smaller --max-step")
    print(info)
    print("angle_deg,fx_n,fy_n,fz_n,f_n,linear_fx_n,linear_fy_n,linear_fz_n,linear_f_n,newton_iterations,seconds")
    for a, r, lf in zip(angles, results, linear):
        f = r["force"]
        print(
            f"{a:g},{f[0]:.6e},{f[1]:.6e},{f[2]:.6e},{np.linalg.norm(f):.6e},"
            f"{lf[0]:.6e},{lf[1]:.6e},{lf[2]:.6e},{np.linalg.norm(lf):.6e},{r['iterations']},{r['seconds']:.2f}"
        )


if __name__ == "__main__":
    main(sys.argv[1:])
