#!/usr/bin/python3
"""Cross-check of neo_hookean.py with CalculiX (ccx, Debian's calculix-ccx) on the same mesh.

    ccx_check.py --mesh flap.msh --fix-box ... --grasp SPEC [--axis-point ...] [--angles 5,15,45]
                 [--workdir DIR] [--ccx ccx]

Writes DIR/lift.inp: the mesh as C3D4 elements, *HYPERELASTIC, NEO HOOKE
with C10 = mu/2 and D1 = 2/K (K = lambda + 2 mu / 3: CalculiX's and Abaqus's
U = C10 (Ibar1 - 3) + (J - 1)^2 / D1, initial shear modulus 2 C10 and bulk
modulus 2 / D1), one NLGEOM *STATIC step per angle whose *BOUNDARY moves the
grasped nodes to their positions at that angle (ramped linearly within the
step from the previous angle's positions), and *NODE PRINT of the total
reaction force RF on the grasped nodes. Runs ccx, reads the totals at the end
of each step, and prints them beside neo_hookean.py's answers with the law
"ccx" (the same strain energy) and the default law.

Not part of the CTest suite (ccx is not a dependency of palpate): install it
by hand (apt-get install calculix-ccx) to run this.
"""

import argparse
import math
import os
import re
import subprocess
import sys
import time

import numpy as np

import lift
import neo_hookean as nh


def num(v):
    # CalculiX reads fields of at most 20 characters: 13 significant digits.
    return f"{v:.12e}"


def write_inp(path, X, T, fixed, grasped, positions, young, nu, max_increment):
    mu, lam = nh.lame(young, nu)
    kappa = lam + 2 * mu / 3
    with open(path, "w") as f:
        f.write("*HEADING\nlift: neo_hookean.py cross-check\n*NODE, NSET=NALL\n")
        for i, p in enumerate(X):
            f.write(f"{i + 1}, {num(p[0])}, {num(p[1])}, {num(p[2])}\n")
        f.write("*ELEMENT, TYPE=C3D4, ELSET=EALL\n")
        for e, t in enumerate(T):
            f.write(f"{e + 1}, {t[0] + 1}, {t[1] + 1}, {t[2] + 1}, {t[3] + 1}\n")
        for name, ids in (("FIX", fixed), ("GRASP", grasped)):
            f.write(f"*NSET, NSET={name}\n")
            for k in range(0, len(ids), 8):
                f.write(", ".join(str(int(i) + 1) for i in ids[k : k + 8]) + "\n")
        f.write("*MATERIAL, NAME=TISSUE\n*HYPERELASTIC, NEO HOOKE\n")
        f.write(f"{num(mu / 2)}, {num(2 / kappa)}\n")
        f.write("*SOLID SECTION, ELSET=EALL, MATERIAL=TISSUE\n")
        for pos in positions:
            f.write("*STEP, NLGEOM, INC=1000\n*STATIC\n")
            f.write(f"{max_increment}, 1.0, 1e-6, {max_increment}\n")
            f.write("*BOUNDARY\nFIX, 1, 3, 0.\n")
            for v, p in zip(grasped, pos):
                for a in range(3):
                    f.write(f"{int(v) + 1}, {a + 1}, {a + 1}, {num(p[a] - X[v][a])}\n")
            f.write("*NODE PRINT, NSET=GRASP, TOTALS=ONLY\nRF\n*END STEP\n")


def read_totals(dat_path):
    """[(time, force [3])] of every 'total force' block in a .dat file."""
    out = []
    with open(dat_path) as f:
        lines = f.read().splitlines()
    for i, line in enumerate(lines):
        m = re.search(r"total force \(fx,fy,fz\) for set GRASP and time\s+(\S+)", line)
        if m:
            for follow in lines[i + 1 : i + 4]:
                parts = follow.split()
                if len(parts) == 3:
                    out.append((float(m.group(1)), np.array([float(p) for p in parts])))
                    break
    return out


def main(argv):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--mesh", required=True)
    ap.add_argument("--fix-box", type=lift.floats(6))
    ap.add_argument("--grasp", required=True)
    ap.add_argument("--angles", default="5,15,45")
    ap.add_argument("--axis-point", type=lift.floats(3), default=[0.0, 0.0, 0.005])
    ap.add_argument("--axis-direction", type=lift.floats(3), default=[0.0, -1.0, 0.0])
    ap.add_argument("--motion", default="rigid")
    ap.add_argument("-E", type=float, default=20e3)
    ap.add_argument("--nu", type=float, default=0.45)
    ap.add_argument("--workdir", default="ccx_work")
    ap.add_argument("--ccx", default="ccx")
    ap.add_argument("--max-increment", type=float, default=0.25, help="largest ccx increment, fraction of a step")
    a = ap.parse_args(argv)
    X, T, fixed, _ = lift.load_mesh(a.mesh, a.fix_box)
    surface = nh.boundary_vertices(T)
    grasped = np.setdiff1d(lift.select_grasp(a.grasp, X, surface), fixed)
    angles = [float(s) for s in a.angles.split(",")]
    rad = [math.radians(s) for s in angles]
    target = lift.motion(a.motion, X[grasped], a.axis_point, a.axis_direction)
    os.makedirs(a.workdir, exist_ok=True)
    inp = os.path.join(a.workdir, "lift.inp")
    write_inp(inp, X, T, fixed, grasped, [target(t) for t in rad], a.E, a.nu, a.max_increment)
    t0 = time.perf_counter()
    env = dict(os.environ, OMP_NUM_THREADS="1", CCX_NPROC_EQUATION_SOLVER="1")
    run = subprocess.run([a.ccx, "-i", "lift"], cwd=a.workdir, env=env, capture_output=True, text=True)
    t_ccx = time.perf_counter() - t0
    if run.returncode != 0 or "ERROR" in run.stdout:
        sys.exit(f"ccx_check.py: ccx failed (exit {run.returncode}); see {a.workdir}/lift.inp\n{run.stdout[-2000:]}")
    totals = read_totals(os.path.join(a.workdir, "lift.dat"))
    at_step_end = {}
    for t, f in totals:
        k = round(t)
        if abs(t - k) < 1e-9 and 1 <= k <= len(angles):
            at_step_end[k] = f
    ours = {}
    for law in ("ccx", "neo-hookean"):
        t1 = time.perf_counter()
        res = nh.solve_path(nh.Solid(X, T, a.E, a.nu, law), fixed, grasped, target, rad, max_step=math.radians(15))
        ours[law] = ([r["force"] for r in res], time.perf_counter() - t1)
    print(f"# {len(X)} vertices, {len(T)} tetrahedra, {len(grasped)} grasped; ccx {t_ccx:.1f} s, "
          f"neo_hookean.py law ccx {ours['ccx'][1]:.1f} s, law neo-hookean {ours['neo-hookean'][1]:.1f} s")
    print("angle_deg,ccx_fx,ccx_fy,ccx_fz,ours_ccx_law_fx,fy,fz,rel_diff,ours_default_law_fx,fy,fz,rel_diff")
    for k, ang in enumerate(angles, start=1):
        c = at_step_end.get(k)
        o1, o2 = ours["ccx"][0][k - 1], ours["neo-hookean"][0][k - 1]
        if c is None:
            print(f"{ang:g},ccx gave no total at the end of step {k}")
            continue
        d1 = np.linalg.norm(o1 - c) / np.linalg.norm(c)
        d2 = np.linalg.norm(o2 - c) / np.linalg.norm(c)
        print(f"{ang:g},{c[0]:.5e},{c[1]:.5e},{c[2]:.5e},{o1[0]:.5e},{o1[1]:.5e},{o1[2]:.5e},{d1:.2e},"
              f"{o2[0]:.5e},{o2[1]:.5e},{o2[2]:.5e},{d2:.2e}")


if __name__ == "__main__":
    main(sys.argv[1:])
