#!/usr/bin/python3
"""Format 1.1's /visualization datasets and the XDMF sidecars, read by
independent readers.

Runs palpate-precompute on the sample organ, then:
- recomputes the softness map from /compliance/G with numpy (largest
  eigenvalue of each 3 x 3 diagonal block, and the same as the largest
  displacement a unit force produces, by SVD), the fixed flags from
  /mesh/fixed_vertex_ids, and the input hash (unchanged from 1.0);
- reads both sidecars (X.xdmf, the volume; X.surface.xdmf, the surface) with
  meshio.read as a researcher would (Debian's python3-meshio, which reads XDMF
  with HDF5 heavy data through h5py) and compares points, cells and arrays
  with the HDF5 datasets;
- checks each sidecar's XML against what ParaView's Xdmf3 reader needs
  (xdmf3_problems below), every DataItem against the HDF5 dataset it names;
- checks --no-xdmf, --xdmf, and the output names the sidecar cannot describe.
Usage: xdmf_test.py PRECOMPUTE
"""
import contextlib
import hashlib
import io
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


def meshio_read(path):
    """meshio.read, with its failure as an AssertionError: meshio prints why a
    file is unreadable and then calls sys.exit(1)."""
    printed = io.StringIO()
    try:
        with contextlib.redirect_stdout(printed):
            return meshio.read(path)
    except (SystemExit, meshio.ReadError) as e:
        raise AssertionError(f"meshio cannot read {path}: {printed.getvalue().strip()} {e!r}") from None


# What ParaView's Xdmf3 reader (the xdmf library, github.com/live-clones/xdmf)
# accepts, as far as the sidecars use it. DataType/NumberType and Precision
# -> array type: XdmfArrayType::InitTypes. Note "Int" with Precision 1 is not
# there: Xdmf3 falls back to Int32 for it; int8 is "Char".
XDMF3_TYPES = {("CHAR", "1"): "int8", ("SHORT", "2"): "int16", ("INT", "4"): "int32", ("INT", "8"): "int64",
               ("FLOAT", "4"): "float32", ("FLOAT", "8"): "float64", ("UCHAR", "1"): "uint8",
               ("USHORT", "2"): "uint16", ("UINT", "4"): "uint32"}
# XdmfTopologyType (those a tetrahedral mesh and its surface need), with the
# nodes per element; XdmfAttributeCenter; XdmfAttributeType.
XDMF3_TOPOLOGIES = {"TRIANGLE": 3, "TETRAHEDRON": 4}
XDMF3_CENTERS = {"GRID", "CELL", "FACE", "EDGE", "NODE", "OTHER"}
XDMF3_ATTRIBUTE_TYPES = {"NONE", "SCALAR", "VECTOR", "TENSOR", "MATRIX", "TENSOR6", "GLOBALID"}


def xdmf3_problems(xdmf_path):
    """What in the XDMF file at xdmf_path ParaView's Xdmf3 reader would
    refuse or misread, checked against the HDF5 files it refers to: a list of
    messages, empty if none."""
    problems = []
    root = ET.parse(xdmf_path).getroot()
    directory = os.path.dirname(xdmf_path)

    def one_of(element, *keys):
        # Xdmf3 reads "Type" before the XDMF 2 spelling; meshio refuses both.
        present = [k for k in keys if k in element.attrib]
        if len(present) != 1:
            problems.append(f"<{element.tag} {element.attrib}>: expected exactly one of {keys}")
            return None
        return element.get(present[0])

    def data_item(parent):
        """The shape and dtype of the dataset parent's one DataItem reads, or None."""
        items = list(parent)
        if len(items) != 1 or items[0].tag != "DataItem":
            problems.append(f"<{parent.tag}>: expected one DataItem, found {[i.tag for i in items]}")
            return None
        item = items[0]
        where = f"DataItem {item.text!r}"
        if item.get("Format") != "HDF":
            problems.append(f"{where}: Format {item.get('Format')!r}, expected HDF")
            return None
        number_type = one_of(item, "DataType", "NumberType")
        declared = XDMF3_TYPES.get(((number_type or "").upper(), item.get("Precision")))
        if declared is None:
            problems.append(f"{where}: type {number_type}/{item.get('Precision')} is not an Xdmf3 array type")
        file_name, colon, dataset = (item.text or "").strip().partition(":")
        if not colon or os.path.isabs(file_name) or os.sep in file_name:
            problems.append(f"{where}: expected '<file name beside the sidecar>:/dataset'")
            return None
        try:
            with h5py.File(os.path.join(directory, file_name), "r") as f:
                d = f.get(dataset)
                if not isinstance(d, h5py.Dataset):
                    problems.append(f"{where}: no dataset {dataset} in {file_name}")
                    return None
                shape, dtype = d.shape, d.dtype
        except OSError as e:
            problems.append(f"{where}: cannot open {file_name}: {e}")
            return None
        dims = tuple(int(n) for n in item.get("Dimensions", "").split())
        if dims != shape:
            problems.append(f"{where}: Dimensions {dims}, the dataset is {shape}")
        if declared is not None and np.dtype(declared) != dtype.newbyteorder("="):
            problems.append(f"{where}: declared {declared}, the dataset is {dtype}")
        return shape

    def uniform_grid(grid):
        name = f"grid {grid.get('Name')!r}"
        tags = [c.tag for c in grid]
        # One each: Xdmf3 keeps the last Topology or Geometry it meets (XdmfGrid::populateItem).
        for tag in ("Topology", "Geometry"):
            if tags.count(tag) != 1:
                problems.append(f"{name}: {tags.count(tag)} <{tag}>, expected 1")
                return
        for c in grid:
            if c.tag not in ("Topology", "Geometry", "Attribute", "Information", "Time"):
                problems.append(f"{name}: unexpected <{c.tag}> in a Uniform grid")
        topology, geometry = grid.find("Topology"), grid.find("Geometry")
        kind = (one_of(topology, "Type", "TopologyType") or "").upper()
        cells = data_item(topology)
        if kind not in XDMF3_TOPOLOGIES:
            problems.append(f"{name}: TopologyType {kind!r}, expected one of {sorted(XDMF3_TOPOLOGIES)}")
        elif cells is not None:
            nodes = XDMF3_TOPOLOGIES[kind]
            if cells[1:] != (nodes,):
                problems.append(f"{name}: {kind} connectivity of shape {cells}, expected (n, {nodes})")
            if topology.get("NumberOfElements") != str(cells[0]):
                problems.append(f"{name}: NumberOfElements {topology.get('NumberOfElements')}, "
                                f"the dataset has {cells[0]}")
            if topology.get("NodesPerElement", str(nodes)) != str(nodes):
                problems.append(f"{name}: NodesPerElement {topology.get('NodesPerElement')}, expected {nodes}")
        if one_of(geometry, "Type", "GeometryType") != "XYZ":
            problems.append(f"{name}: GeometryType {geometry.attrib}, expected XYZ")
        points = data_item(geometry)
        if points is not None and points[1:] != (3,):
            problems.append(f"{name}: points of shape {points}, expected (V, 3)")
        names = [a.get("Name") for a in grid.iter("Attribute")]
        if None in names or len(set(names)) != len(names):
            problems.append(f"{name}: attribute names {names}, expected distinct names")
        for a in grid.iter("Attribute"):
            where = f"{name}, attribute {a.get('Name')!r}"
            center = (a.get("Center") or "").upper()
            if center not in XDMF3_CENTERS:
                problems.append(f"{where}: Center {a.get('Center')!r}, expected one of {sorted(XDMF3_CENTERS)}")
            kind_of = ([a.get(k) for k in ("Type", "AttributeType") if k in a.attrib] or ["Scalar"])[0]
            if kind_of.upper() not in XDMF3_ATTRIBUTE_TYPES:
                problems.append(f"{where}: AttributeType {kind_of!r}")
            shape = data_item(a)
            if shape is None or points is None or cells is None:
                continue
            expected = {"NODE": points[0], "CELL": cells[0]}.get(center)
            if kind_of.upper() == "SCALAR" and shape not in ((expected,), (expected, 1)):
                problems.append(f"{where}: {center} scalar of shape {shape}, expected ({expected},)")

    def grid(g):
        kind = g.get("GridType", "Uniform")
        if kind == "Uniform":
            uniform_grid(g)
        elif kind == "Collection" and g.get("CollectionType", "Spatial") in ("Spatial", "Temporal"):
            for child in g.findall("Grid"):
                grid(child)
        else:
            problems.append(f"grid {g.get('Name')!r}: GridType {kind!r}")

    if root.tag != "Xdmf" or root.get("Version") != "3.0":
        problems.append(f"root <{root.tag} {root.attrib}>, expected <Xdmf Version=\"3.0\">")
    domains = list(root)
    if [d.tag for d in domains] != ["Domain"]:
        return problems + [f"expected one <Domain>, found {[d.tag for d in domains]}"]
    grids = list(domains[0])
    if not grids or any(g.tag != "Grid" for g in grids):
        return problems + [f"<Domain> holds {[g.tag for g in grids]}, expected grids"]
    for g in grids:
        grid(g)
    return problems


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


class SidecarsThroughMeshioAndTheXdmf3Checks(unittest.TestCase):
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
        cls.surface_xdmf = os.path.join(d, "organ.surface.xdmf")
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
        self.assertTrue(os.path.isfile(self.surface_xdmf))
        self.assertEqual([f for f in os.listdir(self.dir.name) if ".tmp-" in f], [])

    def test_each_sidecar_is_one_uniform_grid_with_relative_references(self):
        # meshio.read takes one <Domain> holding one grid, whose children are
        # only Topology, Geometry, Attribute and Information (meshio/xdmf/main.py).
        for path, name in [(self.xdmf, "volume"), (self.surface_xdmf, "surface")]:
            with self.subTest(path=path):
                root = ET.parse(path).getroot()
                (domain,) = list(root)
                (grid,) = list(domain)
                self.assertEqual((grid.tag, grid.get("Name"), grid.get("GridType")), ("Grid", name, "Uniform"))
                self.assertTrue({c.tag for c in grid} <= {"Topology", "Geometry", "Attribute"})
                for item in root.iter("DataItem"):
                    self.assertTrue(item.text.startswith("organ.h5:/"), item.text)  # relative

    def test_paraview_xdmf3_would_read_each_sidecar(self):
        for path in (self.xdmf, self.surface_xdmf):
            with self.subTest(path=path):
                self.assertEqual(xdmf3_problems(path), [])

    def test_a_float32_file_has_sidecars_of_the_same_types(self):
        # --precision float32 stores G only in float32; the datasets the
        # sidecars name keep their types, which the check compares.
        d = self.dir.name
        run("--mesh", os.path.join(d, "organ.msh"), "-E", "85e3", "--nu", "0.45", "--fix-sphere", "-0.03", "0",
            "0.04", "0.03", "--precision", "float32", "-o", os.path.join(d, "organ32.h5"), "-q")
        for name in ("organ32.xdmf", "organ32.surface.xdmf"):
            with self.subTest(name=name):
                self.assertEqual(xdmf3_problems(os.path.join(d, name)), [])
                self.assertTrue(np.array_equal(meshio_read(os.path.join(d, name)).points, self.h5["/mesh/vertices"]))

    def test_the_xdmf3_check_finds_what_it_is_for(self):
        # The check itself, on broken copies of the sidecar: each must be caught.
        with open(self.xdmf, encoding="utf-8") as f:
            text = f.read()
        V, T = len(self.h5["/mesh/vertices"]), len(self.h5["/mesh/tetrahedra"])
        broken = [
            ("dims", f'Dimensions="{V} 3"', f'Dimensions="{V + 1} 3"'),
            ("count", f'NumberOfElements="{T}"', f'NumberOfElements="{T - 1}"'),
            ("dtype", 'DataType="Char" Precision="1"', 'DataType="Int" Precision="1"'),
            ("path", "organ.h5:/visualization/fixed", "organ.h5:/visualization/missing"),
            ("center", 'Center="Cell"', 'Center="Node"'),
            ("grids", "</Grid>", "</Grid><Grid/>"),
        ]
        for what, good, bad in broken:
            with self.subTest(what=what):
                self.assertIn(good, text)
                path = os.path.join(self.dir.name, f"broken-{what}.xdmf")
                with open(path, "w", encoding="utf-8") as f:
                    f.write(text.replace(good, bad, 1))
                self.assertNotEqual(xdmf3_problems(path), [])

    def check_points_and_vertex_arrays(self, m):
        # meshio copies the HDF5 datasets through h5py, no arithmetic: equal to the bit.
        X = self.h5["/mesh/vertices"]
        self.assertEqual(m.points.dtype, np.float64)
        self.assertEqual(m.points.shape, (self.report["mesh"]["vertices"], 3))
        self.assertTrue(np.array_equal(m.points, X))
        # In metres: the bounding box the report gives in metres (printed
        # with round-trip precision, so 1e-12 m only absorbs formatting).
        self.assertLessEqual(np.max(np.abs(m.points.min(axis=0) - self.report["mesh"]["bbox_min_m"])), 1e-12)
        self.assertLessEqual(np.max(np.abs(m.points.max(axis=0) - self.report["mesh"]["bbox_max_m"])), 1e-12)
        pd = m.point_data
        self.assertEqual(sorted(pd), ["fixed", "softness_m_per_n", "source_vertex_id"])
        self.assertEqual(pd["softness_m_per_n"].dtype, np.float64)
        self.assertEqual(pd["fixed"].dtype, np.int8)
        self.assertTrue(np.array_equal(pd["softness_m_per_n"], self.h5["/visualization/softness"]))
        self.assertTrue(np.array_equal(pd["fixed"], self.h5["/visualization/fixed"]))
        self.assertTrue(np.array_equal(pd["source_vertex_id"], self.h5["/mesh/source_vertex_ids"]))

    def test_meshio_reads_the_volume(self):
        m = meshio_read(self.xdmf)
        self.assertEqual([c.type for c in m.cells], ["tetra"])
        self.assertEqual(len(m.cells[0].data), self.report["mesh"]["tetrahedra"])
        self.assertTrue(np.array_equal(m.cells[0].data, self.h5["/mesh/tetrahedra"]))
        self.check_points_and_vertex_arrays(m)
        self.assertEqual(sorted(m.cell_data), ["material"])
        (material,) = m.cell_data["material"]
        self.assertTrue(np.array_equal(material, self.h5["/mesh/tetrahedron_material"]))
        self.assertEqual(sorted(set(material.tolist())), [0, 1])  # organ and tumour

    def test_meshio_reads_the_surface(self):
        m = meshio_read(self.surface_xdmf)
        self.assertEqual([c.type for c in m.cells], ["triangle"])
        self.assertEqual(len(m.cells[0].data), self.report["mesh"]["surface_triangles"])
        self.assertTrue(np.array_equal(m.cells[0].data, self.h5["/mesh/surface_triangles"]))
        self.check_points_and_vertex_arrays(m)
        self.assertEqual(m.cell_data, {})

    def test_the_files_move_together(self):
        with tempfile.TemporaryDirectory() as elsewhere:
            for name in ("organ.h5", "organ.xdmf", "organ.surface.xdmf"):
                shutil.copy(os.path.join(self.dir.name, name), elsewhere)
            for name in ("organ.xdmf", "organ.surface.xdmf"):
                m = meshio_read(os.path.join(elsewhere, name))
                self.assertTrue(np.array_equal(m.point_data["softness_m_per_n"], self.h5["/visualization/softness"]))
                self.assertEqual(xdmf3_problems(os.path.join(elsewhere, name)), [])


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
        self.assertEqual(sorted(os.listdir(self.dir.name)), ["a.h5", "job.toml", "organ.msh"])
        with open(self.path("job.toml")) as f:
            self.assertIn("xdmf = false", f.read())
        # The job file says no; the flag says yes.
        run("-j", self.path("job.toml"), "-o", self.path("b.h5"), "--xdmf", "-q")
        self.assertTrue(os.path.exists(self.path("b.xdmf")))
        self.assertTrue(os.path.exists(self.path("b.surface.xdmf")))
        run("-j", self.path("job.toml"), "-o", self.path("c.h5"), "-q")
        self.assertFalse(os.path.exists(self.path("c.xdmf")))
        self.assertFalse(os.path.exists(self.path("c.surface.xdmf")))

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
