#!/usr/bin/python3
"""scripts/session_report.py, and the session file layout, read with h5py.

palpate_session_writer_for_tests writes a known session (described in
tests/session_writer_for_tests.cpp) once closed and once killed before
closing. The assessment is checked against values computed by hand here,
against the summary attributes the recorder computed itself (two
implementations of docs/session-recording.md), and on the crashed
"<file>.partial". The layout is checked against the document's tables; the
script's errors are one line and exit code 2.
Usage: session_report_test.py WRITER SCRIPT
"""
import json
import os
import signal
import subprocess
import sys
import tempfile
import unittest

import h5py
import numpy as np

WRITER = None
SCRIPT = None

# Hand-computed from the session's definition (see the writer's comment).
# left: contact intervals are opened by ticks 200..699 (500 ms), grasping by
# 500..599 and 650..699 (150 ms); ∫|f|dt = (350·2 + 149·3 + 5) N·ms = 1.152 N·s.
# right: contact opened by ticks 100..199, 100 · 2 ms, at 1 N.
EXPECTED = {
    "left": dict(ticks=1000, duration_s=0.999, time_in_contact_s=0.5, time_grasping_s=0.15,
                 max_force_n=5.0, mean_force_in_contact_n=1.152 / 0.5, max_grip_n=2.5,
                 path_length_m=0.0999, grasps=2),
    "right": dict(ticks=500, duration_s=0.998, time_in_contact_s=0.2, time_grasping_s=0.0,
                  max_force_n=1.0, mean_force_in_contact_n=1.0, max_grip_n=0.0,
                  path_length_m=0.499, grasps=0),
}
# Times and positions are k·1e-3 etc. in float64: sums of up to 1000 such
# intervals carry ~1e-13 relative rounding; 1e-9 is loose and still exact
# enough to tell one tick (1e-3 of the total) apart.
REL = 1e-9

# docs/session-recording.md: every dataset of /tools/<id>, its dtype and
# its row width (None: 1-D).
TOOL_DATASETS = {
    "time_s": ("<f8", None), "sequence": ("<u8", None), "send_time_ns": ("<i8", None),
    "position": ("<f8", 3), "orientation": ("<f8", 4), "jaw_angle": ("<f8", None),
    "force": ("<f8", 3), "torque": ("<f8", 3), "grip": ("<f8", None), "state": ("|i1", None),
    "watchdog": ("|u1", None), "force_limited": ("|u1", None), "held": ("<u4", None),
    "compute_ns": ("<u8", None), "contact_start": ("<u8", None), "contact_count": ("<u4", None),
    "contacts/vertex": ("<u4", None), "contacts/force": ("<f8", 3),
}
EVENT_DATASETS = {"time_s": "<f8", "tool": "<i4", "kind": "<i4", "pose_sequence": "<u8"}


def report(*args):
    return subprocess.run(["/usr/bin/python3", SCRIPT, *args], capture_output=True, text=True)


class SessionReport(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.dir = tempfile.TemporaryDirectory()
        cls.closed = os.path.join(cls.dir.name, "closed.h5")
        p = subprocess.run([WRITER, cls.closed], capture_output=True, text=True)
        assert p.returncode == 0, p.stderr
        crashed = os.path.join(cls.dir.name, "crashed.h5")
        p = subprocess.run([WRITER, crashed, "--crash"], capture_output=True, text=True)
        assert p.returncode == -signal.SIGKILL, (p.returncode, p.stderr)
        assert not os.path.exists(crashed)
        cls.partial = crashed + ".partial"

    @classmethod
    def tearDownClass(cls):
        cls.dir.cleanup()

    def check_assessment(self, tools, complete):
        self.assertEqual([t["id"] for t in tools], ["left", "right"])
        for tool in tools:
            with self.subTest(tool=tool["id"]):
                for key, value in EXPECTED[tool["id"]].items():
                    if isinstance(value, int):
                        self.assertEqual(tool[key], value, key)
                    else:
                        self.assertAlmostEqual(tool[key], value, delta=REL * max(1.0, abs(value)),
                                               msg=key)
                self.assertEqual(tool["dropped_ticks"], 0 if complete else None)

    def test_json_of_a_closed_session_matches_the_hand_computed_values(self):
        p = report(self.closed, "--json")
        self.assertEqual(p.returncode, 0, p.stderr)
        r = json.loads(p.stdout)
        self.assertTrue(r["complete"])
        self.assertEqual(r["model_id"], "sample-organ")
        self.assertEqual(r["started_utc"], "2023-11-14T22:13:20.000Z")
        self.assertEqual(r["dropped_events"], 0)
        self.check_assessment(r["tools"], complete=True)

    def test_script_and_recorder_agree_on_every_summary_attribute(self):
        r = json.loads(report(self.closed, "--json").stdout)
        with h5py.File(self.closed, "r") as f:
            for tool in r["tools"]:
                a = f["tools"][tool["id"]].attrs
                for key in EXPECTED["left"]:
                    self.assertAlmostEqual(float(a[key]), tool[key],
                                           delta=1e-12 * max(1.0, abs(tool[key])),
                                           msg=f"{tool['id']} {key}")
                self.assertEqual(int(a["dropped_ticks"]), tool["dropped_ticks"])
                self.assertEqual(int(a["truncated_contact_ticks"]), 0)

    def test_table(self):
        p = report(self.closed)
        self.assertEqual(p.returncode, 0, p.stderr)
        lines = p.stdout.splitlines()
        header = next(line for line in lines if line.startswith("tool"))
        for column in ["ticks", "duration s", "in contact s", "grasping s", "max force N",
                       "mean force in contact N", "max grip N", "path m", "grasps", "dropped"]:
            self.assertIn(column, header)
        left = next(line for line in lines if line.startswith("left")).split()
        self.assertEqual(left, ["left", "1000", "0.999", "0.500", "0.150", "5.000", "2.304",
                                "2.500", "0.0999", "2", "0"])
        self.assertIn("closed", p.stdout)

    def test_a_crashed_recording_is_readable_up_to_its_last_flush(self):
        # The writer was killed after its last flush: everything is there,
        # without the summary attributes that close() writes.
        with h5py.File(self.partial, "r") as f:
            self.assertNotIn("closed_utc", f.attrs)
            self.assertNotIn("ticks", f["tools/left"].attrs)
            self.assertEqual(len(f["events/kind"]), 8)
        p = report(self.partial, "--json")
        self.assertEqual(p.returncode, 0, p.stderr)
        r = json.loads(p.stdout)
        self.assertFalse(r["complete"])
        self.check_assessment(r["tools"], complete=False)
        p = report(self.partial)
        self.assertIn("INCOMPLETE", p.stdout)
        self.assertIn("?", next(line for line in p.stdout.splitlines() if line.startswith("left")))

    def test_layout(self):
        with h5py.File(self.closed, "r") as f:
            a = f.attrs
            self.assertEqual(a["format"], "palpate-session")
            self.assertEqual(int(a["format_version"]), 1)
            self.assertEqual(a["units"], "m, N, s, rad")
            self.assertEqual(int(a["start_unix_ns"]), 1_700_000_000_000_000_000)
            self.assertRegex(a["closed_utc"], r"^\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{3}Z$")
            self.assertEqual(int(a["ticks"]), 1500)
            self.assertEqual(int(a["events"]), 8)
            self.assertEqual(list(f["tools"].attrs["ids"]), ["left", "right"])
            for tool, n in [("left", 1000), ("right", 500)]:
                g = f["tools"][tool]
                for name, (dtype, width) in TOOL_DATASETS.items():
                    with self.subTest(tool=tool, dataset=name):
                        d = g[name]
                        self.assertEqual(d.dtype.str, dtype)
                        self.assertEqual(d.ndim, 1 if width is None else 2)
                        if width is not None:
                            self.assertEqual(d.shape[1], width)
                        self.assertIsNone(d.compression)
                        if not name.startswith("contacts/"):
                            self.assertEqual(d.shape[0], n)
                # The contact arrays are indexed by contact_start/contact_count.
                start, count = g["contact_start"][:], g["contact_count"][:]
                np.testing.assert_array_equal(start[1:], np.cumsum(count)[:-1])
                self.assertEqual(len(g["contacts/vertex"]), int(count.sum()))
                self.assertEqual(len(g["contacts/force"]), int(count.sum()))
                self.assertEqual(list(g["state"].attrs["names"]), ["free", "touching", "grasping"])
                self.assertEqual(g["force"].attrs["units"], "N")
            left = f["tools/left"]
            # Tick 250 touches with 1 + 250 mod 3 = 2 contacts sharing its 2 N on the organ.
            s, c = int(left["contact_start"][250]), int(left["contact_count"][250])
            self.assertEqual(c, 2)
            np.testing.assert_array_equal(left["contacts/force"][s:s + c], [[0, 0, -1], [0, 0, -1]])
            np.testing.assert_array_equal(left["contacts/vertex"][s:s + c], [0, 1])
            for name, dtype in EVENT_DATASETS.items():
                self.assertEqual(f["events"][name].dtype.str, dtype)
            names = list(f["events/kind"].attrs["names"])
            self.assertEqual([names[k] for k in f["events/kind"][:]],
                             ["touch", "grasp", "release", "grasp", "release", "leave", "touch",
                              "leave"])
            np.testing.assert_array_equal(f["events/tool"][:], [0, 0, 0, 0, 0, 0, 1, 1])

    def check_refused(self, path, fragment):
        p = report(path)
        self.assertEqual(p.returncode, 2, p.stdout + p.stderr)
        self.assertEqual(p.stdout, "")
        self.assertEqual(len(p.stderr.strip().splitlines()), 1, p.stderr)
        self.assertTrue(p.stderr.startswith("session_report: error: "), p.stderr)
        self.assertIn(path, p.stderr)
        self.assertIn(fragment, p.stderr)

    def test_missing_file(self):
        self.check_refused(os.path.join(self.dir.name, "nothing.h5"), "no such file")

    def test_not_hdf5(self):
        path = os.path.join(self.dir.name, "notes.txt")
        with open(path, "w") as f:
            f.write("not a recording\n")
        self.check_refused(path, "not an HDF5 file")

    def test_foreign_hdf5_files(self):
        compliance = os.path.join(self.dir.name, "organ.h5")
        with h5py.File(compliance, "w") as f:
            f.attrs["format"] = "palpate-compliance"
        self.check_refused(compliance, "a 'palpate-compliance' file, not a palpate session")
        bare = os.path.join(self.dir.name, "bare.h5")
        with h5py.File(bare, "w") as f:
            f["x"] = np.arange(3)
        self.check_refused(bare, "without a 'format' attribute")
        future = os.path.join(self.dir.name, "future.h5")
        with h5py.File(future, "w") as f:
            f.attrs["format"] = "palpate-session"
            f.attrs["format_version"] = np.int32(2)
        self.check_refused(future, "format_version 2")


if __name__ == "__main__":
    WRITER, SCRIPT = sys.argv[1], sys.argv[2]
    unittest.main(argv=sys.argv[:1], verbosity=2)
