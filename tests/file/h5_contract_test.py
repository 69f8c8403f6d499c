#!/usr/bin/python3
"""The compliance file read by an independent reader (h5py + numpy).

Runs palpate-precompute on the sample organ, then checks every item of the
contract in docs/compliance-file.md and recomputes G with a stiffness matrix
assembled here, in numpy, from the textbook B^T D B element: an implementation
that shares no code with palpate's. Also checks the command line's error
behaviour (one line, exit code, no file). Usage: h5_contract_test.py PRECOMPUTE
"""
import json
import os
import subprocess
import sys
import tempfile
import unittest

import h5py
import numpy as np

PRECOMPUTE = None


def run(*args, check=True):
    p = subprocess.run([PRECOMPUTE, *args], capture_output=True, text=True)
    if check and p.returncode != 0:
        raise AssertionError(f"{args} exited {p.returncode}: {p.stderr}")
    return p


def element_stiffness(P, lam, mu):
    """V B^T D B for a P1 tetrahedron (rows of P are its vertices)."""
    A = np.hstack([np.ones((4, 1)), P])
    C = np.linalg.inv(A)  # column i: coefficients of barycentric lambda_i
    V = abs(np.linalg.det(A)) / 6
    B = np.zeros((6, 12))
    for i in range(4):
        gx, gy, gz = C[1:, i]
        B[:, 3 * i:3 * i + 3] = [[gx, 0, 0], [0, gy, 0], [0, 0, gz], [0, gz, gy], [gz, 0, gx], [gy, gx, 0]]
    D = np.zeros((6, 6))
    D[:3, :3] = lam
    D[:3, :3] += 2 * mu * np.eye(3)
    D[3:, 3:] = mu * np.eye(3)
    return V * B.T @ D @ B


class ComplianceFileContract(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.dir = tempfile.TemporaryDirectory()
        d = cls.dir.name
        cls.mesh = os.path.join(d, "organ.msh")
        cls.out = os.path.join(d, "organ.h5")
        run("make-sample", "-o", cls.mesh, "--size", "0.025", "-q")
        p = run("--mesh", cls.mesh, "-E", "85e3", "--nu", "0.45", "--group-material", "tumour:340e3:0.45",
                "--fix-sphere", "-0.03", "0", "0.04", "0.03", "-o", cls.out, "--json", "-q")
        cls.report = json.loads(p.stdout)
        cls.f = h5py.File(cls.out, "r")

    @classmethod
    def tearDownClass(cls):
        cls.f.close()
        cls.dir.cleanup()

    def test_root_attributes(self):
        a = self.f.attrs
        self.assertEqual(a["format"], "palpate-compliance")
        self.assertEqual(int(a["format_version_major"]), 1)
        self.assertTrue(a["producer"].startswith("palpate-precompute "))
        self.assertEqual(a["method"], "both")
        self.assertIn("m/N", a["units"])
        self.assertIn("E = 85000 Pa", a["material_summary"])
        self.assertRegex(a["created_utc"], r"^\d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ$")
        self.assertRegex(a["input_hash"], r"^sha256:[0-9a-f]{64}$")
        self.assertIn("[material]", a["job_toml"])
        self.assertEqual(json.loads(a["report_json"])["input_hash"], a["input_hash"])

    def test_shapes_types_and_ranges(self):
        X = self.f["/mesh/vertices"]
        T = self.f["/mesh/tetrahedra"]
        ids = self.f["/compliance/vertex_ids"][:]
        G = self.f["/compliance/G"]
        self.assertEqual(X.dtype, np.float64)
        self.assertEqual(X.shape[1], 3)
        self.assertEqual(T.shape[1], 4)
        nv = X.shape[0]
        self.assertTrue((T[:] >= 0).all() and (T[:] < nv).all())
        self.assertEqual(G.shape, (3 * len(ids), 3 * len(ids)))
        self.assertEqual(G.dtype, np.float64)
        self.assertEqual(self.f["/mesh/tetrahedron_material"].shape, (T.shape[0],))
        self.assertEqual(list(self.f["/material/young_modulus_pa"][:]), [85e3, 340e3])
        names = [n.decode() if isinstance(n, bytes) else n for n in self.f["/material/name"][:]]
        self.assertEqual(names, ["organ", "tumour"])
        # Metres: the sample organ is 160 mm long.
        extent = X[:].max(axis=0) - X[:].min(axis=0)
        self.assertAlmostEqual(extent[0], 0.16, delta=0.005)

    def test_compliance_vertices_are_the_free_surface_vertices(self):
        tris = self.f["/mesh/surface_triangles"][:]
        fixed = set(self.f["/mesh/fixed_vertex_ids"][:].tolist())
        ids = self.f["/compliance/vertex_ids"][:].tolist()
        surface = set(tris.ravel().tolist())
        self.assertTrue(fixed)
        self.assertEqual(set(ids), surface - fixed)
        self.assertEqual(ids, sorted(ids))
        # Outward orientation: the enclosed volume by the divergence theorem is positive
        # and equals the tetrahedra's.
        X = self.f["/mesh/vertices"][:]
        a, b, c = X[tris[:, 0]], X[tris[:, 1]], X[tris[:, 2]]
        v_surface = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6
        T = self.f["/mesh/tetrahedra"][:]
        p0, p1, p2, p3 = (X[T[:, i]] for i in range(4))
        v_tets = np.einsum("ij,ij->i", p1 - p0, np.cross(p2 - p0, p3 - p0)).sum() / 6
        self.assertGreater(v_surface, 0)
        self.assertAlmostEqual(v_surface / v_tets, 1.0, delta=1e-12)

    def test_G_equals_an_independent_dense_computation(self):
        X = self.f["/mesh/vertices"][:]
        T = self.f["/mesh/tetrahedra"][:]
        mat = self.f["/mesh/tetrahedron_material"][:]
        E = self.f["/material/young_modulus_pa"][:]
        nu = self.f["/material/poisson_ratio"][:]
        lam = E * nu / ((1 + nu) * (1 - 2 * nu))
        mu = E / (2 * (1 + nu))
        n = X.shape[0]
        K = np.zeros((3 * n, 3 * n))
        for t in range(T.shape[0]):
            ke = element_stiffness(X[T[t]], lam[mat[t]], mu[mat[t]])
            dofs = (3 * T[t][:, None] + np.arange(3)).ravel()
            K[np.ix_(dofs, dofs)] += ke
        fixed = self.f["/mesh/fixed_vertex_ids"][:]
        free = np.setdiff1d(np.arange(n), fixed)
        free_dofs = (3 * free[:, None] + np.arange(3)).ravel()
        Kf = K[np.ix_(free_dofs, free_dofs)]
        ids = self.f["/compliance/vertex_ids"][:]
        pos = {v: i for i, v in enumerate(free)}
        rows = np.array([3 * pos[v] + a for v in ids for a in range(3)])
        E_S = np.zeros((Kf.shape[0], len(rows)))
        E_S[rows, np.arange(len(rows))] = 1
        G_ref = np.linalg.solve(Kf, E_S)[rows, :]
        G = self.f["/compliance/G"][:]
        # kappa(K) ~ 1e5 for nu = 0.45: two double-precision solvers agree to ~1e-11.
        rel = np.abs(G - G_ref).max() / np.abs(G_ref).max()
        self.assertLess(rel, 1e-9)
        # Row a, column b: G[3a+i, 3b+j] is vertex a's displacement along i per newton on b along j.
        a, b = 3, len(ids) - 2
        f = np.zeros(3 * len(ids))
        f[3 * b + 2] = 1.0
        self.assertAlmostEqual(G[3 * a + 0, 3 * b + 2], (G_ref @ f)[3 * a], delta=1e-9 * np.abs(G_ref).max())

    def test_G_symmetric_with_spd_diagonal_blocks(self):
        G = self.f["/compliance/G"][:]
        self.assertLess(np.abs(G - G.T).max() / np.abs(G).max(), 1e-10)
        for k in range(G.shape[0] // 3):
            B = G[3 * k:3 * k + 3, 3 * k:3 * k + 3]
            self.assertGreater(np.linalg.eigvalsh(0.5 * (B + B.T)).min(), 0)

    def test_report_checks(self):
        c = self.report["checks"]
        self.assertLess(c["max_relative_difference"], 1e-8)
        self.assertLess(c["max_residual"], 1e-10)
        self.assertIn("blas", self.report)


class CommandLineErrors(unittest.TestCase):
    def setUp(self):
        self.dir = tempfile.TemporaryDirectory()
        self.mesh = os.path.join(self.dir.name, "organ.msh")
        self.out = os.path.join(self.dir.name, "out.h5")
        run("make-sample", "-o", self.mesh, "--size", "0.03", "-q")

    def tearDown(self):
        self.dir.cleanup()

    def check_error(self, code, fragment, *args):
        p = run(*args, "-o", self.out, check=False)
        self.assertEqual(p.returncode, code, p.stderr)
        lines = p.stderr.strip().splitlines()
        self.assertEqual(len(lines), 1, p.stderr)
        self.assertTrue(lines[0].startswith("palpate-precompute: error: "), lines[0])
        self.assertIn(fragment, lines[0])
        self.assertFalse(os.path.exists(self.out))
        self.assertEqual([f for f in os.listdir(self.dir.name) if ".tmp-" in f], [])

    def test_bad_inputs(self):
        base = ["--mesh", self.mesh, "--fix-sphere", "-0.03", "0", "0.04", "0.03"]
        self.check_error(2, "Young's modulus", *base, "-E", "0", "--nu", "0.45")
        self.check_error(2, "Poisson ratio", *base, "-E", "1e5", "--nu", "0.7")
        self.check_error(2, "no such file", "--mesh", "/nonexistent.msh", "-E", "1e5", "--nu", "0.4", "--fix-ids", "x")
        self.check_error(2, "method", *base, "-E", "1e5", "--nu", "0.4", "--method", "magic")
        two = os.path.join(self.dir.name, "two.txt")
        with open(two, "w") as f:
            f.write("0\n1\n")
        self.check_error(2, "rigid motions", "--mesh", self.mesh, "-E", "1e5", "--nu", "0.4", "--fix-ids", two)
        self.check_error(4, "needs about", *base, "-E", "1e5", "--nu", "0.4", "--memory-limit-gb", "1e-6")

    def test_save_job_reproduces_the_hash(self):
        job = os.path.join(self.dir.name, "job.toml")
        run("--mesh", self.mesh, "-E", "1e5", "--nu", "0.4", "--fix-sphere", "-0.03", "0", "0.04", "0.03",
            "--method", "solves", "-o", self.out, "--save-job", job, "-q")
        again = os.path.join(self.dir.name, "again.h5")
        run("--job", job, "-o", again, "-q")
        with h5py.File(self.out) as a, h5py.File(again) as b:
            self.assertEqual(a.attrs["input_hash"], b.attrs["input_hash"])
            self.assertTrue(np.array_equal(a["/compliance/G"][:], b["/compliance/G"][:]))


if __name__ == "__main__":
    PRECOMPUTE = sys.argv.pop(1)
    unittest.main(verbosity=2)
