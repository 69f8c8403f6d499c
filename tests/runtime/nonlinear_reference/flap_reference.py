#!/usr/bin/python3
"""The flap of issue 18: nonlinear (Neo-Hookean) and linear grasp forces, as a Markdown table.

    flap_reference.py --mesh flap.msh --compliance flap.h5 [--grasp NAME ...] [--angles 5,15,30,45,60]

flap.msh and flap.h5 come from flap_mesh.py and palpate-precompute (README.md).
Prints Markdown on stdout: per grasp definition, per angle, the summed force
that the grasp exerts on the flap (N), nonlinear and linear (W^-1 d from G).
"""

import argparse
import math
import sys
import time

import numpy as np

import lift
import neo_hookean as nh
from flap_mesh import read_msh2

L, WIDTH, T = 0.1, 0.04, 0.01
E = 1e-4  # m: selection slack, below any mesh spacing used here

# name -> (grasp spec, motion, axis height z (m), description)
GRASPS = {
    "face-rigid": (
        f"box:{L - E},-1,-1,1,1,1",
        "rigid",
        T / 2,
        "every vertex of the tip end face x = L, rotated rigidly by theta about the y-axis through (0, y, T/2)",
    ),
    "face-translate": (
        f"box:{L - E},-1,-1,1,1,1",
        "translate",
        T / 2,
        "every vertex of the tip end face, translated by the arc motion of the face's centre (0.1, 0, T/2) "
        "about the same axis, without rotating",
    ),
    "pinch": (
        f"surface-box:{L - E},{-T / 3 - E},{T - E},1,{T / 3 + E},1+surface-box:{L - E},{-T / 3 - E},-1,1,{T / 3 + E},{E}",
        "rigid",
        T / 2,
        "the vertices of the tip's top and bottom edges (x = L, z = 0 and z = T) with |y| <= 3.33 mm "
        "(jaws closed on the tip's centre), rotated rigidly about the y-axis through (0, y, T/2)",
    ),
    "top-patch": (
        f"surface-box:{L - T - E},{-T / 2 - E},{T - E},1,{T / 2 + E},1",
        "rigid",
        0.0,
        "the top-face vertices with x >= L - 10 mm and |y| <= 5 mm, rotated rigidly about the y-axis through (0, y, 0)",
    ),
}


def run_grasp(solid, X, surface, fixed, compliance, name, angles):
    spec, kind, z_axis, _ = GRASPS[name]
    grasped = np.setdiff1d(lift.select_grasp(spec, X, surface), fixed)
    target = lift.motion(kind, X[grasped], (0.0, 0.0, z_axis), (0.0, -1.0, 0.0))
    rad = [math.radians(a) for a in angles]
    linear = lift.linear_forces_from_compliance(compliance, grasped, [target(t) - X[grasped] for t in rad])
    t0 = time.perf_counter()
    results = nh.solve_path(solid, fixed, grasped, target, rad, max_step=math.radians(15))
    return grasped, results, linear, time.perf_counter() - t0


def vec(f):
    return f"({f[0]:+.4f}, {f[1]:+.4f}, {f[2]:+.4f})"


def angle_between(a, b):
    c = np.dot(a, b) / (np.linalg.norm(a) * np.linalg.norm(b))
    return math.degrees(math.acos(max(-1.0, min(1.0, c))))


def main(argv):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--mesh", required=True)
    ap.add_argument("--compliance", required=True)
    ap.add_argument("--grasp", action="append", choices=sorted(GRASPS))
    ap.add_argument("--angles", default="5,15,30,45,60")
    ap.add_argument("--law", default="neo-hookean", choices=nh.LAWS)
    a = ap.parse_args(argv)
    X, T_ = read_msh2(a.mesh)
    solid = nh.Solid(X, T_, 20e3, 0.45, a.law)
    surface = nh.boundary_vertices(T_)
    fixed = np.nonzero(X[:, 0] < E)[0]
    angles = [float(s) for s in a.angles.split(",")]
    for name in a.grasp or sorted(GRASPS):
        grasped, results, linear, seconds = run_grasp(solid, X, surface, fixed, a.compliance, name, angles)
        print(f"\n### Grasp `{name}`: {GRASPS[name][3]}\n")
        print(f"{len(grasped)} grasped vertices; law {a.law}; {seconds:.1f} s for the path.\n")
        print("| θ | nonlinear force (N) | \\|f\\| | linear force (N) | \\|f\\| | linear error | direction |")
        print("|---|---|---|---|---|---|---|")
        for ang, r, lf in zip(angles, results, linear):
            f = r["force"]
            err = np.linalg.norm(lf - f) / np.linalg.norm(f)
            print(
                f"| {ang:g}° | {vec(f)} | {np.linalg.norm(f):.4f} | {vec(lf)} | {np.linalg.norm(lf):.4f} "
                f"| {100 * err:,.0f} % | {angle_between(f, lf):.0f}° |"
            )
        sys.stdout.flush()


if __name__ == "__main__":
    main(sys.argv[1:])
