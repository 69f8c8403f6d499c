#!/usr/bin/python3
"""Format 1.1's /visualization datasets and the XDMF sidecar, read by
independent readers.

Runs palpate-precompute on the sample organ, then:
- recomputes the softness map from /compliance/G with numpy (largest
  eigenvalue of each 3 x 3 diagonal block, and the same as the largest
  displacement a unit force produces, by SVD), the fixed flags from
  /mesh/fixed_vertex_ids, and the input hash (unchanged from 1.0);
- reads the sidecar with meshio (Debian's python3-meshio, which reads XDMF
  with HDF5 heavy data through h5py) and compares points, cells and arrays
  with the HDF5 datasets. meshio 5 reads one grid per file ("Only supports
  one grid right now"), and the sidecar holds two in a spatial collection,
  so each grid is copied, unchanged, into a one-grid XDMF file beside the
  original and read from there;
- checks --no-xdmf, --xdmf, and the output names the sidecar cannot describe.
Usage: xdmf_test.py PRECOMPUTE
"""
import hashlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
import unittest
import xml.etree.ElementTree as ET

import h5py
import meshio
import numpy as np

PRECOMPUTE = None

# numpy's eigvalsh and svd on a 3 x 3 block in double: a few ulps of the
# block's norm. The file's values come from Eigen's solver on the same
# float64 G, so the two agree far below this.
REL_TOL = 1e-12


def run(*args, check=True):
    p = subprocess.run([PRECOMPUTE, *args], capture_output=True, text=True)
    if check and p.returncode != 0:
        raise AssertionError(f"{args} exited {p.returncode}: {p.stderr}")
    return p


def one_grid_files(xdmf_path):
    """For each Uniform grid of the sidecar, a one-grid XDMF file next to it
    (same directory: the HDF5 references are relative). Returns {name: path}."""
    tree = ET.parse(xdmf_path)
    root = tree.getroot()
    out = {}
    for grid in root.iter("Grid"):
        if grid.get("GridType") != "Uniform":
            continue
        xdmf = ET.Element("Xdmf", root.attrib)
        ET.SubElement(xdmf, "Domain").append(grid)
        path = os.path.join(os.path.dirname(xdmf_path), f"only-{grid.get('Name')}.xdmf")
        ET.ElementTree(xdmf).write(path, encoding="utf-8", xml_declaration=True)
        out[grid.get("Name")] = path
    return out


class Version1_1(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.dir = tempfile.TemporaryDirectory()
        d = cls.dir.name
        cls.mesh = os.path.join(d, "organ.msh")
        cls.out = os.path.join(d, "organ.h5")
        run("make-sample", "-o", cls.mesh, "--size", "0.025", "-q")
        cls.args = ["--mesh", cls.mesh, "-E", "85e3", "--nu", "0.45", "--group-material", "tumour:340e3:0.45",
                    "--fix-sphere", "-0.03", "0", "0.04", "0.03"]
        p = run(*cls.args, "-o", cls.out, "--json", "-q")
        cls.report = json.loads(p.stdout)
        cls.f = h5py.File(cls.out, "r")

    @classmethod
    def tearDownClass(cls):
        cls.f.close()
        cls.dir.cleanup()

    def test_version_1_1(self):
        self.assertEqual(int(self.f.attrs["format_version_major"]), 1)
        # 1.1 or later (1.2 adds content_sha256, docs/compliance-file.md).
        self.assertGreaterEqual(int(self.f.attrs["format_version_minor"]), 1)

    def test_input_hash_is_the_same_as_in_1_0(self):
        # docs/compliance-file.md, "input_hash": 1.1 adds datasets but hashes
        # the problem as 1.0 did, preamble included, so the hash of one
        # problem does not change with the minor version.
        f = self.f
        h = hashlib.sha256()
        h.update(b"palpate-compliance 1.0\n")
        X = f["/mesh/vertices"][()].astype("<f8")
        T = f["/mesh/tetrahedra"][()].astype("<i4")
        h.update(f"vertices {X.shape[0]}\n".encode())
        h.update(X.tobytes())
        h.update(f"tetrahedra {T.shape[0]}\n".encode())
        h.update(T.tobytes())
        h.update(f["/mesh/tetrahedron_material"][()].astype("<i4").tobytes())
        for E, nu in zip(f["/material/young_modulus_pa"][()], f["/material/poisson_ratio"][()]):
            h.update(("material %.17g %.17g\n" % (E, nu)).encode())
        fixed = f["/mesh/fixed_vertex_ids"][()].astype("<i4")
        h.update(f"fixed {len(fixed)}\n".encode())
        h.update(fixed.tobytes())
        self.assertEqual(f.attrs["input_hash"], "sha256:" + h.hexdigest())

    def test_softness_is_the_largest_eigenvalue_of_each_diagonal_block(self):
        s = self.f["/visualization/softness"]
        self.assertEqual(s.dtype, np.float64)
        self.assertEqual(s.attrs["units"], "m/N")
        s = s[()]
        V = self.f["/mesh/vertices"].shape[0]
        self.assertEqual(s.shape, (V,))
        G = self.f["/compliance/G"][()]
        ids = self.f["/compliance/vertex_ids"][()]
        for a, v in enumerate(ids):
            B = G[3 * a:3 * a + 3, 3 * a:3 * a + 3]
            lam = np.linalg.eigvalsh(0.5 * (B + B.T)).max()
            # The largest displacement (m) 1 N on the vertex produces there: ||B||_2.
            push = np.linalg.svd(B, compute_uv=False).max()
            self.assertGreater(lam, 0)
            self.assertLessEqual(abs(s[v] - lam), REL_TOL * lam, f"vertex {v}")
            self.assertLessEqual(abs(s[v] - push), REL_TOL * lam, f"vertex {v}")
        others = np.setdiff1d(np.arange(V), ids)
        self.assertTrue((s[others] == 0).all())
        # Softest where the organ is free, stiffest near the attachment: the
        # softest vertex is far from the fixed sphere (centre -0.03, 0, 0.04).
        X = self.f["/mesh/vertices"][()]
        d = np.linalg.norm(X - [-0.03, 0, 0.04], axis=1)
        self.assertGreater(d[np.argmax(s)], 0.06)

    def test_fixed_flags_match_the_fixed_vertex_ids(self):
        fixed = self.f["/visualization/fixed"]
        self.assertEqual(fixed.dtype, np.int8)
        fixed = fixed[()]
        self.assertEqual(fixed.shape, (self.f["/mesh/vertices"].shape[0],))
        self.assertTrue(np.isin(fixed, [0, 1]).all())
        self.assertTrue(np.array_equal(np.flatnonzero(fixed), self.f["/mesh/fixed_vertex_ids"][()]))
        s = self.f["/visualization/softness"][()]
        self.assertTrue((s[fixed == 1] == 0).all())

    def test_float32_files_hold_the_softness_of_the_float64_G(self):
        out32 = os.path.join(self.dir.name, "organ32.h5")
        run(*self.args, "--precision", "float32", "-o", out32, "-q")
        with h5py.File(out32, "r") as f32:
            self.assertEqual(f32["/compliance/G"].dtype, np.float32)
            s32 = f32["/visualization/softness"][()]
            G32 = f32["/compliance/G"][()].astype(np.float64)
        s = self.f["/visualization/softness"][()]
        ids = self.f["/compliance/vertex_ids"][()]
        self.assertTrue(np.all(np.abs(s32 - s) <= REL_TOL * s))
        # From the rounded G the values would differ by ~1e-8.
        rounded = np.array([np.linalg.eigvalsh(G32[3 * a:3 * a + 3, 3 * a:3 * a + 3]).max()
                            for a in range(len(ids))])
        self.assertGreater(np.max(np.abs(rounded - s[ids]) / s[ids]), 100 * REL_TOL)


class SidecarThroughMeshio(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.dir = tempfile.TemporaryDirectory()
        d = cls.dir.name
        mesh = os.path.join(d, "organ.msh")
        cls.out = os.path.join(d, "organ.h5")
        run("make-sample", "-o", mesh, "--size", "0.025", "-q")
        p = run("--mesh", mesh, "-E", "85e3", "--nu", "0.45", "--group-material", "tumour:340e3:0.45",
                "--fix-sphere", "-0.03", "0", "0.04", "0.03", "-o", cls.out, "--json", "-q")
        cls.report = json.loads(p.stdout)
        cls.xdmf = os.path.join(d, "organ.xdmf")
        with h5py.File(cls.out, "r") as f:
            cls.h5 = {k: f[k][()] for k in ["/mesh/vertices", "/mesh/tetrahedra", "/mesh/surface_triangles",
                                            "/mesh/tetrahedron_material", "/mesh/source_vertex_ids",
                                            "/visualization/softness", "/visualization/fixed"]}

    @classmethod
    def tearDownClass(cls):
        cls.dir.cleanup()

    def test_the_report_names_the_sidecar(self):
        self.assertEqual(self.report["output"]["xdmf"], self.xdmf)
        self.assertTrue(os.path.isfile(self.xdmf))
        self.assertEqual([f for f in os.listdir(self.dir.name) if ".tmp-" in f], [])

    def test_structure(self):
        root = ET.parse(self.xdmf).getroot()
        self.assertEqual(root.tag, "Xdmf")
        self.assertEqual(root.get("Version"), "3.0")
        (domain,) = list(root)
        (collection,) = list(domain)
        self.assertEqual(collection.get("GridType"), "Collection")
        self.assertEqual(collection.get("CollectionType"), "Spatial")
        self.assertEqual([g.get("Name") for g in collection], ["volume", "surface"])
        for item in root.iter("DataItem"):
            self.assertEqual(item.get("Format"), "HDF")
            self.assertTrue(item.text.startswith("organ.h5:/"), item.text)  # relative

    def check_vertex_arrays(self, m):
        self.assertTrue(np.array_equal(m.points, self.h5["/mesh/vertices"]))
        self.assertEqual(m.points.dtype, np.float64)
        pd = m.point_data
        self.assertEqual(sorted(pd), ["fixed", "softness_m_per_n", "source_vertex_id"])
        self.assertEqual(pd["softness_m_per_n"].dtype, np.float64)
        self.assertTrue(np.array_equal(pd["softness_m_per_n"], self.h5["/visualization/softness"]))
        self.assertTrue(np.array_equal(pd["fixed"], self.h5["/visualization/fixed"]))
        self.assertTrue(np.array_equal(pd["source_vertex_id"], self.h5["/mesh/source_vertex_ids"]))

    def test_meshio_reads_the_volume_grid(self):
        m = meshio.read(one_grid_files(self.xdmf)["volume"])
        self.assertEqual(len(m.points), self.report["mesh"]["vertices"])
        self.assertEqual([c.type for c in m.cells], ["tetra"])
        self.assertEqual(len(m.cells[0].data), self.report["mesh"]["tetrahedra"])
        self.assertTrue(np.array_equal(m.cells[0].data, self.h5["/mesh/tetrahedra"]))
        self.check_vertex_arrays(m)
        (material,) = m.cell_data["material"]
        self.assertTrue(np.array_equal(material, self.h5["/mesh/tetrahedron_material"]))
        self.assertEqual(sorted(set(material.tolist())), [0, 1])  # organ and tumour

    def test_meshio_reads_the_surface_grid(self):
        m = meshio.read(one_grid_files(self.xdmf)["surface"])
        self.assertEqual(len(m.points), self.report["mesh"]["vertices"])
        self.assertEqual([c.type for c in m.cells], ["triangle"])
        self.assertEqual(len(m.cells[0].data), self.report["mesh"]["surface_triangles"])
        self.assertTrue(np.array_equal(m.cells[0].data, self.h5["/mesh/surface_triangles"]))
        self.check_vertex_arrays(m)
        self.assertEqual(m.cell_data, {})

    def test_the_pair_moves_together(self):
        with tempfile.TemporaryDirectory() as elsewhere:
            for name in ("organ.h5", "organ.xdmf"):
                shutil.copy(os.path.join(self.dir.name, name), elsewhere)
            m = meshio.read(one_grid_files(os.path.join(elsewhere, "organ.xdmf"))["surface"])
            self.assertTrue(np.array_equal(m.point_data["softness_m_per_n"], self.h5["/visualization/softness"]))


class CommandLine(unittest.TestCase):
    def setUp(self):
        self.dir = tempfile.TemporaryDirectory()
        self.mesh = os.path.join(self.dir.name, "organ.msh")
        run("make-sample", "-o", self.mesh, "--size", "0.03", "-q")
        self.base = ["--mesh", self.mesh, "-E", "1e5", "--nu", "0.4", "--fix-sphere", "-0.03", "0", "0.04", "0.03",
                     "--method", "solves", "-q"]

    def tearDown(self):
        self.dir.cleanup()

    def path(self, name):
        return os.path.join(self.dir.name, name)

    def test_no_xdmf_and_xdmf(self):
        p = run(*self.base, "-o", self.path("a.h5"), "--no-xdmf", "--json", "--save-job", self.path("job.toml"))
        self.assertIsNone(json.loads(p.stdout)["output"]["xdmf"])
        self.assertTrue(os.path.exists(self.path("a.h5")))
        self.assertFalse(os.path.exists(self.path("a.xdmf")))
        with open(self.path("job.toml")) as f:
            self.assertIn("xdmf = false", f.read())
        # The job file says no; the flag says yes.
        run("-j", self.path("job.toml"), "-o", self.path("b.h5"), "--xdmf", "-q")
        self.assertTrue(os.path.exists(self.path("b.xdmf")))
        run("-j", self.path("job.toml"), "-o", self.path("c.h5"), "-q")
        self.assertFalse(os.path.exists(self.path("c.xdmf")))

    def test_output_names_the_sidecar_cannot_describe(self):
        for name, fragment in [("organ.xdmf", "its own XDMF sidecar"), ("a:b.h5", "contains ':'")]:
            p = run(*self.base, "-o", self.path(name), check=False)
            self.assertEqual(p.returncode, 2, p.stderr)
            lines = p.stderr.strip().splitlines()
            self.assertEqual(len(lines), 1, p.stderr)
            self.assertTrue(lines[0].startswith("palpate-precompute: error: output "), lines[0])
            self.assertIn(fragment, lines[0])
            self.assertIn("--no-xdmf", lines[0])
            self.assertEqual(sorted(os.listdir(self.dir.name)), ["organ.msh"])
        run(*self.base, "-o", self.path("a:b.h5"), "--no-xdmf")
        self.assertTrue(os.path.exists(self.path("a:b.h5")))


if __name__ == "__main__":
    PRECOMPUTE = sys.argv.pop(1)
    unittest.main(verbosity=2)
