#!/usr/bin/python3
"""palpate's sphere press against an independent finite-element contact
solution (issue 17; docs/model/contact-reference.md, "An independent check of the contact").

Makes the sample organ (8 mm tetrahedra, the demo's materials and attachment),
presses a frictionless rigid 5 mm sphere into it at three points, and a 20 mm
one at one of them, 1 to 5 mm,
with palpate's ToolContactEngine (palpate_sphere_press: 200 ticks per
millimetre, 300 held ticks, the mean of the last 75), and solves the same
press with reference_contact.py: its own stiffness K from the mesh and
materials of the file, its own factorization, non-penetration at lattice
samples of every surface triangle near the sphere plus refinement at the
points still penetrated, an exact least-distance solve per linearization and a
fixed point on the sphere's normals. Same mesh, same material, same
attachment: what differs is how the contact is found and solved.

Tolerances, per press (force along the press, relative to the reference):
- the reference itself: its compliance on the contact vertices equals the
  file's G to 1e-9 (the same model; 7e-14 measured), its normals' fixed point
  converged (change < 1e-9), no triangle penetrated by more than 1e-4 r
  (after refinement: < 1e-5 r measured) and its forces move by < 0.3 % from
  lattice level 4 to 8 (measured 0.23 % at most: the refinement, not the
  lattice, places the active samples);
- a press whose held force is steady in palpate (its last 75 ticks within
  0.1 %: the tick-to-tick iteration reached a fixed point): within 1 %
  (measured 0.3 % at most: the same fixed point, up to the reference's
  refinement tolerance);
- a press whose contact set still alternates from tick to tick (a limit
  cycle, or no cycle at all): the mean force within 5 %, issue 34's target
  for every press. Since frictionless points' loads are placed by the
  secant step (docs/tools.md, "Where a frictionless point pushes"), 19 of
  the 20 presses are steady (within 0.2 %); the 20 mm sphere at 1 mm still
  alternates (held ticks 3.4 % below to 0.4 % above, mean −1.5 %). Before,
  8 alternated, and on `lower_face_x0_y30` at 4 and 5 mm the cycle's mean
  was 7 % and 13 % below the reference (docs/model/contact-reference.md).

Usage: sphere_press_test.py PRECOMPUTE SPHERE_PRESS
"""
import json
import os
import subprocess
import sys
import tempfile
import unittest

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import reference_contact  # noqa: E402

PRECOMPUTE = SPHERE_PRESS = None
ENV = dict(os.environ, OPENBLAS_NUM_THREADS="1")

DEPTHS_MM = (1, 2, 3, 4, 5)
FIVE_PERCENT = {d: 0.05 for d in DEPTHS_MM}  # issue 34's target at every depth

# The sample organ is an ellipsoid, semi-axes 80 x 50 x 40 mm: a point aimed
# at on its lower (or upper) face, moved onto the mesh; pressed along the ellipsoid's
# outward normal there. Tolerance per depth (mm), see the docstring.
SCENARIOS = {
    "lower_face_x20_y10": dict(aim=(0.02, 0.01), radius_mm=5,
                       alternating_tolerance=FIVE_PERCENT),
    "lower_face_x0_y30": dict(aim=(0.0, 0.03), radius_mm=5,
                              alternating_tolerance=FIVE_PERCENT),
    "upper_face_x40_ym10": dict(aim=(0.04, -0.01), side=1, radius_mm=5,
                                alternating_tolerance=FIVE_PERCENT),
    # A wide tip (a palpating finger, a retractor): 20 mm, over twice the
    # triangles' size, where palpate's contact set never settles.
    "lower_face_x20_y10_wide": dict(aim=(0.02, 0.01), radius_mm=20,
                                    alternating_tolerance=FIVE_PERCENT),
}
STEADY_TOLERANCE = 0.01


def run(*args):
    p = subprocess.run(args, capture_output=True, text=True, env=ENV)
    if p.returncode != 0:
        raise AssertionError(f"{args} exited {p.returncode}: {p.stderr}")
    return p.stdout


def ellipsoid_point(x, y, side=-1):
    a, b, c = 0.08, 0.05, 0.04
    z = side * c * np.sqrt(1 - (x / a) ** 2 - (y / b) ** 2)
    n = np.array([x / a ** 2, y / b ** 2, z / c ** 2])
    return np.array([x, y, z]), n / np.linalg.norm(n)


class SpherePress(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.dir = tempfile.TemporaryDirectory()
        d = cls.dir.name
        mesh, model = os.path.join(d, "organ.msh"), os.path.join(d, "organ.h5")
        run(PRECOMPUTE, "make-sample", "-o", mesh, "--size", "0.008", "-q")
        run(PRECOMPUTE, "--mesh", mesh, "-E", "85e3", "--nu", "0.45",
            "--group-material", "tumour:340e3:0.45", "--fix-sphere", "-0.03", "0", "0.04", "0.025",
            "--method", "solves", "--no-xdmf", "-q", "-o", model)
        cls.organ = reference_contact.Organ(model)
        cls.results = {}
        for name, s in SCENARIOS.items():
            aim, normal = ellipsoid_point(*s["aim"], s.get("side", -1))
            point = reference_contact.surface_point(cls.organ, aim)
            palpate = json.loads(run(
                SPHERE_PRESS, model, "--point", ",".join(repr(v) for v in point),
                "--normal", ",".join(repr(v) for v in normal),
                "--radius-mm", str(s["radius_mm"]),
                "--depths-mm", ",".join(str(v) for v in DEPTHS_MM)))
            depths = [p["depth_m"] for p in palpate["presses"]]
            r = 1e-3 * s["radius_mm"]
            reference = reference_contact.press(cls.organ, point, normal, r, depths, level=8)
            coarse = reference_contact.press(cls.organ, point, normal, r, depths, level=4)
            cls.results[name] = (palpate, reference, coarse)
            print(f"{name}: depth mm, reference N, palpate N (held min-max), difference")
            for p, q in zip(palpate["presses"], reference):
                print(f"  {1e3 * p['depth_m']:.0f}  {q['force_n']:.4f}  {p['force_n']:.4f} "
                      f"({p['force_min_n']:.4f}-{p['force_max_n']:.4f})  "
                      f"{100 * (p['force_n'] / q['force_n'] - 1):+.2f} %", file=sys.stderr)

    @classmethod
    def tearDownClass(cls):
        cls.dir.cleanup()

    def test_reference_is_converged_on_the_same_model(self):
        for name, (palpate, reference, coarse) in self.results.items():
            r = palpate["radius_m"]
            for q, q4 in zip(reference, coarse):
                with self.subTest(scenario=name, depth_mm=1e3 * q["depth_m"]):
                    agreement = reference_contact.compliance_agreement(
                        self.organ, q["compliance_vertices"], q["compliance_block_m_per_n"])
                    self.assertLess(agreement, 1e-9)
                    self.assertLess(q["normal_change"], 1e-9)
                    self.assertLess(q["max_penetration_m"], 1e-4 * r)
                    self.assertLess(q["max_gap_violation_m"], 1e-9 * r)
                    self.assertLess(abs(q4["force_n"] / q["force_n"] - 1), 0.003)
                    self.assertGreater(q["force_n"], 0)

    def test_palpate_force_matches_the_reference(self):
        for name, (palpate, reference, _) in self.results.items():
            tolerance = SCENARIOS[name]["alternating_tolerance"]
            for p, q in zip(palpate["presses"], reference):
                depth_mm = round(1e3 * p["depth_m"])
                with self.subTest(scenario=name, depth_mm=depth_mm):
                    steady = p["force_max_n"] - p["force_min_n"] <= 1e-3 * p["force_n"]
                    bound = STEADY_TOLERANCE if steady else tolerance[depth_mm]
                    difference = p["force_n"] / q["force_n"] - 1
                    self.assertLess(abs(difference), bound,
                                    f"palpate {p['force_n']:.4f} N, reference {q['force_n']:.4f} N "
                                    f"({'steady' if steady else 'alternating'})")

    def test_a_steady_press_does_not_penetrate(self):
        """Where palpate's ticks reach a fixed point, its deformed surface
        (its loads through the reference's own K) stays outside the sphere
        to 1 % of r: the same contact solution, not a coincidence of forces."""
        for name, (palpate, reference, _) in self.results.items():
            r = palpate["radius_m"]
            tris = self.organ.triangles
            for p in palpate["presses"]:
                if p["force_max_n"] - p["force_min_n"] > 1e-3 * p["force_n"]:
                    continue
                with self.subTest(scenario=name, depth_mm=1e3 * p["depth_m"]):
                    loads = {}
                    for load in p["loads"]:
                        v = int(self.organ.compliance_ids[load["compliance_index"]])
                        loads[v] = loads.get(v, 0) + np.array(load["force_n"])
                    y = self.organ.X + self.organ.displacement(loads)
                    dist = reference_contact.triangle_distances(
                        np.array(p["centre_m"]), y[tris[:, 0]], y[tris[:, 1]], y[tris[:, 2]])
                    self.assertGreater(dist.min(), 0.99 * r)


if __name__ == "__main__":
    PRECOMPUTE, SPHERE_PRESS = sys.argv[1], sys.argv[2]
    unittest.main(argv=sys.argv[:1], verbosity=2)
