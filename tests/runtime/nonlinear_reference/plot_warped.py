#!/usr/bin/python3
"""Plots palpate's linear and warped lift forces against the nonlinear reference.

    plot_warped.py PALPATE_LIFT FLAP.h5 LIVER_H8.h5 OUT.png

FLAP.h5 is the flap of flap_mesh.py (3.33 mm) precomputed by palpate; the
nonlinear forces are the ones recorded in flap_reference.md and
liver_reference.md (this directory; they take 10-75 s to recompute with
lift.py). palpate's answers are computed now by PALPATE_LIFT
(lift_palpate.cpp) for the same grasps. docs/model/warped.md, "Large rotations:
warped compliance", shows the result.
"""

import subprocess
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

T = 0.01
CASES = [
    ("flap, pinch", "flap",
     ["--box", "0.0999,-0.00334,-0.0001,1,0.00334,0.0001", "--box", f"0.0999,-0.00334,{T - 1e-4},1,0.00334,{T + 1e-4}",
      "--axis-point", f"0,0,{T / 2}", "--axis-direction", "0,-1,0"],
     {5: (0.0010, 0, 0.0062), 15: (0.0166, 0, 0.0238), 30: (0.0523, 0, 0.0760), 45: (0.0702, 0, 0.1598), 60: (0.0483, 0, 0.2621)}),
    ("flap, top patch", "flap",
     ["--box", "0.0899,-0.0051,0.0099,1,0.0051,1", "--axis-point", "0,0,0", "--axis-direction", "0,-1,0"],
     {5: (-0.0190, 0, 0.0045), 15: (-0.0353, 0, 0.0102), 30: (-0.0257, 0, 0.0335), 45: (-0.0135, 0, 0.0865), 60: (-0.0276, 0, 0.1642)}),
    ("liver h8, lobe edge", "liver",
     ["--sphere", "-0.10316021,-0.02154549,0.12723204,0.008", "--axis-point", "-0.100,0.0085,0.127", "--axis-direction", "0,0,-1"],
     {5: (-0.267, -0.173, -0.095), 15: (-0.703, -0.141, -0.198), 30: (-0.957, 0.827, -0.148), 45: (-0.528, 2.785, 0.108), 60: (0.699, 5.450, 0.501)}),
]


def run(program, model, args, angles):
    out = subprocess.run([program, model, *args, "--angles", ",".join(map(str, angles))],
                         check=True, capture_output=True, text=True).stdout
    rows = {}
    for line in out.splitlines():
        if line and line[0].isdigit():
            t, mode, fx, fy, fz, _, status = line.split(",")
            rows[(int(float(t)), mode)] = np.array([float(fx), float(fy), float(fz)]) if status == "ok" else None
    return rows


def angle(a, b):
    return np.degrees(np.arccos(np.clip(a @ b / (np.linalg.norm(a) * np.linalg.norm(b)), -1, 1)))


def main(program, flap, liver, out_png):
    files = {"flap": flap, "liver": liver}
    fig, axes = plt.subplots(2, 3, figsize=(13, 7))
    for col, (title, which, args, ref) in enumerate(CASES):
        angles = sorted(ref)
        rows = run(program, files[which], args, angles)
        r = {a: np.array(ref[a]) for a in angles}
        top, bottom = axes[0][col], axes[1][col]
        top.plot(angles, [np.linalg.norm(r[a]) for a in angles], "k-o", label="nonlinear (Neo-Hookean)")
        for mode, style in (("linear", "C3--s"), ("warped", "C0-^")):
            pts = [(a, rows[(a, mode)]) for a in angles if rows[(a, mode)] is not None]
            top.plot([a for a, _ in pts], [np.linalg.norm(f) for _, f in pts], style, label=mode)
            bottom.plot([a for a, _ in pts], [angle(f, r[a]) for a, f in pts], style, label=mode)
            print(title, mode, [(a, round(float(np.linalg.norm(f)), 4), round(float(angle(f, r[a])), 1)) for a, f in pts])
        top.set_title(title)
        top.set_yscale("log")
        top.set_ylabel("|force| (N)")
        bottom.set_ylabel("direction error (°)")
        bottom.set_xlabel("lift angle θ (°)")
        for ax in (top, bottom):
            ax.grid(True, alpha=0.3)
        top.legend(fontsize=8)
    fig.suptitle("Grasp and lift: palpate's linear and warped forces against a nonlinear reference "
                 "(a missing warped point: refused, the rotations did not settle)", fontsize=10)
    fig.tight_layout()
    fig.savefig(out_png, dpi=110)
    print("wrote", out_png)


if __name__ == "__main__":
    if len(sys.argv) != 5:
        sys.exit("usage: plot_warped.py PALPATE_LIFT FLAP.h5 LIVER_H8.h5 OUT.png")
    main(*sys.argv[1:])
