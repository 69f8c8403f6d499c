"""content_sha256 (docs/compliance-file.md) checked by an independent reader:
the digest of docs/compliance-file.md's Python snippet, computed with h5py
and hashlib, equals the one palpate-precompute stored, for float64 and
float32 files and a file with a cut region (1.3, whose datasets have their
own digest, cut_region_sha256, so that content_sha256 is what a 1.2 reader
verifies); one flipped byte of G, or of the region's element stiffness,
makes the digest that covers it differ.

Usage: compliance_digest_test.py PALPATE_PRECOMPUTE
"""

import hashlib
import os
import subprocess
import sys
import tempfile
import unittest

import h5py
import numpy as np

PRECOMPUTE = sys.argv.pop(1)

# As in docs/compliance-file.md, "content_sha256: what is hashed".
ORDER = ["/mesh/vertices", "/mesh/tetrahedra", "/mesh/tetrahedron_material",
         "/mesh/surface_triangles", "/mesh/fixed_vertex_ids", "/mesh/source_vertex_ids",
         "/material/name", "/material/young_modulus_pa", "/material/poisson_ratio",
         "/compliance/vertex_ids", "/compliance/G", "/visualization/softness",
         "/visualization/fixed"]
CUT_REGION = ["vertices", "source_vertex_ids", "tetrahedra", "tetrahedron_material",
              "element_stiffness", "vertex_stiffness", "edges", "edge_stiffness",
              "boundary_triangles", "interface_vertices", "interface_compliance_index",
              "fixed_vertices", "density_kg_m3", "damping_per_s", "spec"]


def content_sha256(f, order=ORDER):
    h = hashlib.sha256()
    for path in order:
        d = f[path]
        h.update(f"{path} {'x'.join(str(n) for n in d.shape)}\n".encode())
        if d.dtype.kind == "O":
            for name in d.asstr()[()]:
                h.update(name.encode() + b"\0")
        else:
            h.update(np.ascontiguousarray(d[()]).astype(d.dtype.newbyteorder("<")).tobytes())
    return "sha256:" + h.hexdigest()


def run(*args):
    p = subprocess.run([PRECOMPUTE, *args], capture_output=True, text=True)
    if p.returncode != 0:
        raise AssertionError(f"{args} exited {p.returncode}: {p.stderr}")


class ContentDigest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.dir = tempfile.TemporaryDirectory()
        mesh = os.path.join(cls.dir.name, "organ.msh")
        run("make-sample", "-o", mesh, "--size", "0.03", "-q")
        cls.files = {}
        for precision in ("float64", "float32"):
            out = os.path.join(cls.dir.name, f"{precision}.h5")
            run("--mesh", mesh, "-E", "85e3", "--nu", "0.45", "--fix-sphere", "-0.03", "0", "0.04",
                "0.03", "--precision", precision, "-o", out, "-q", "--no-xdmf")
            cls.files[precision] = out
        # A cut region (docs/precompute.md, "A cuttable region"): a job file,
        # the keys have no flags. The front of the organ, x ≥ 40 mm.
        job = os.path.join(cls.dir.name, "cut.toml")
        cls.cut = os.path.join(cls.dir.name, "cut.h5")
        with open(job, "w") as f:
            f.write(f'[mesh]\nfile = "{mesh}"\n[material]\nyoung_modulus_pa = 85e3\n'
                    'poisson_ratio = 0.45\n[attachment]\n'
                    'spheres = [ { center = [-0.03, 0, 0.04], radius = 0.03 } ]\n'
                    '[cut_region]\nbox_min_mm = [40, -60, -50]\nbox_max_mm = [90, 60, 50]\n'
                    f'[output]\nfile = "{cls.cut}"\nxdmf = false\n')
        run("--job", job, "-q")

    @classmethod
    def tearDownClass(cls):
        cls.dir.cleanup()

    def test_version_1_2_with_a_digest_an_independent_reader_recomputes(self):
        for precision, path in self.files.items():
            with h5py.File(path) as f:
                # 1.3 adds only /cut_region, absent from these files.
                self.assertGreaterEqual(int(f.attrs["format_version_minor"]), 2)
                self.assertNotIn("cut_region", f)
                stored = f.attrs["content_sha256"]
                self.assertRegex(stored, r"^sha256:[0-9a-f]{64}$")
                self.assertEqual(stored, content_sha256(f), precision)
                self.assertEqual(f["/compliance/G"].dtype.itemsize, 4 if precision == "float32" else 8)

    def test_the_digest_covers_the_cut_region(self):
        with h5py.File(self.cut) as f:
            self.assertEqual(int(f.attrs["format_version_minor"]), 3)
            self.assertIn("cut_region", f)
            self.assertEqual(f.attrs["content_sha256"], content_sha256(f))
            region = ["/cut_region/" + n for n in CUT_REGION]
            self.assertEqual(f.attrs["cut_region_sha256"], content_sha256(f, region))
            offset = f["/cut_region/element_stiffness"].id.get_offset()
        data = bytearray(open(self.cut, "rb").read())
        data[offset + 3] ^= 0x01
        flipped = os.path.join(self.dir.name, "cut-flipped.h5")
        with open(flipped, "wb") as out:
            out.write(data)
        with h5py.File(flipped) as f:
            self.assertEqual(f.attrs["content_sha256"], content_sha256(f))
            self.assertNotEqual(f.attrs["cut_region_sha256"], content_sha256(f, region))

    def test_one_flipped_byte_of_G_changes_it(self):
        path = self.files["float64"]
        with h5py.File(path) as f:
            offset = f["/compliance/G"].id.get_offset()
            size = f["/compliance/G"].id.get_storage_size()
        data = bytearray(open(path, "rb").read())
        data[offset + size // 2] ^= 0x01
        flipped = os.path.join(self.dir.name, "flipped.h5")
        with open(flipped, "wb") as out:
            out.write(data)
        with h5py.File(flipped) as f:
            self.assertNotEqual(f.attrs["content_sha256"], content_sha256(f))


if __name__ == "__main__":
    unittest.main()
