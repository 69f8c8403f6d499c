#!/usr/bin/python3
"""The cut demo's gesture cuts while the pliers hold (issue 20, docs/tools.md,
"Cutting"): palpated serves the demo's sample organ with its cuttable region
(config/sample-organ-cut.toml, the mesh scripts/demo.sh makes) and the cut
demo's tools (config/palpated-cut.toml), and palpate-pliers plays
config/gestures/cut.toml over real Cyclone DDS. Then:

- palpated logged cuts by the hook, each removing tetrahedra, the topology
  version increasing with each, the tetrahedra left adding up;
- every contact solve stayed finite (no tool_solve_failed: a region that
  rings under the pliers makes them non-finite);
- the left pliers grasped before the first cut and let go after the last,
  once, and every answer the left tool got while the hook's edge was live
  says it was grasping.
- the hook's touch and leave events are contact episodes: at most two of
  each, though its contact comes and goes every other tick while it cuts.

No timing is asserted: a loaded machine may answer late; only what was
answered is checked. This script runs in a private network namespace whose
only interface is loopback (CTest's palpate_isolated_test) and refuses to
start DDS anywhere else.

Usage: cut_gesture_test.py BUILD_DIR SOURCE_DIR
"""
import csv
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import unittest

BUILD = SOURCE = None
MODEL = "sample-organ-cut"
# The hook's edge is live at or below its grasp angle (config/palpated-cut.toml).
GRASP_ANGLE_DEG = 15


def program(name):
    return os.path.join(BUILD, "bin", name)


def read(path):
    with open(path) as f:
        return f.read()


def interfaces():
    out = subprocess.run(["ip", "-o", "link", "show"], capture_output=True, text=True,
                         check=True).stdout
    return [line.split(": ")[1].split("@")[0] for line in out.splitlines() if ": " in line]


class CutGesture(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        if interfaces() != ["lo"]:
            raise RuntimeError(f"refusing to start DDS outside a private network namespace "
                               f"(interfaces: {interfaces()})")
        cls.work = tempfile.mkdtemp(prefix="palpate-cut-gesture-")
        work = cls.work
        # The demo's sample organ (8 mm tetrahedra) and its cut job, by
        # condensation (the job's "both" cross-checks; that is precompute's test).
        mesh = os.path.join(work, "sample-organ.msh")
        subprocess.run([program("palpate-precompute"), "make-sample", "-o", mesh, "--size",
                        "0.008"], check=True, capture_output=True)
        job = read(os.path.join(SOURCE, "config", "sample-organ-cut.toml"))
        job = job.replace('"../out/sample-organ.msh"', f'"{mesh}"')
        job = job.replace('"../out/sample-organ-cut.h5"', f'"{work}/sample-organ-cut.h5"')
        job = re.sub(r'^method = .*$', 'method = "condensation"', job, flags=re.M)
        with open(os.path.join(work, "cut.toml"), "w") as f:
            f.write(job)
        p = subprocess.run([program("palpate-precompute"), "--job", os.path.join(work, "cut.toml")],
                           capture_output=True, text=True, timeout=300)
        assert p.returncode == 0, p.stdout + p.stderr
        config = read(os.path.join(SOURCE, "config", "palpated-cut.toml"))
        config = config.replace('"../out/sample-organ-cut.h5"', f'"{work}/sample-organ-cut.h5"')
        with open(os.path.join(work, "palpated.toml"), "w") as f:
            f.write(config)

        log_path = os.path.join(work, "palpated.log")
        with open(log_path, "w") as log:
            daemon = subprocess.Popen([program("palpated"), "--config",
                                       os.path.join(work, "palpated.toml")], stderr=log)
        try:
            deadline = time.monotonic() + 60
            while "event=serving" not in read(log_path):
                assert daemon.poll() is None, read(log_path)
                assert time.monotonic() < deadline, "palpated did not start serving"
                time.sleep(0.1)
            cls.csv_path = os.path.join(work, "cut.csv")
            cls.json_path = os.path.join(work, "cut.json")
            cls.pliers = subprocess.run(
                [program("palpate-pliers"), os.path.join(SOURCE, "config", "gestures", "cut.toml"),
                 "--model", MODEL, "--csv", cls.csv_path, "--json", cls.json_path, "-q"],
                capture_output=True, text=True, timeout=120)
        finally:
            daemon.send_signal(signal.SIGTERM)
            cls.daemon_status = daemon.wait(timeout=30)
        cls.log = read(log_path).splitlines()

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.work, ignore_errors=True)

    def lines(self, event, tool=None):
        """(index, fields) of palpated's log lines of this event (and tool)."""
        found = []
        for i, line in enumerate(self.log):
            fields = dict(re.findall(r'(\w+)=("[^"]*"|\S+)', line))
            if fields.get("event") == event and (tool is None or fields.get("tool") == tool):
                found.append((i, fields))
        return found

    def test_the_gesture_was_played_and_palpated_stopped_cleanly(self):
        self.assertEqual(self.pliers.returncode, 0, self.pliers.stdout + self.pliers.stderr)
        self.assertEqual(self.daemon_status, 0, "\n".join(self.log[-5:]))

    def test_the_hook_cuts_the_region(self):
        served = self.lines("cut_region_served")
        self.assertEqual(len(served), 1, "\n".join(self.log[:10]))
        before = int(served[0][1]["tetrahedra"])
        cuts = self.lines("cut", "hook")
        self.assertGreater(len(cuts), 0, "no event=cut line:\n" + "\n".join(self.log[-20:]))
        left, version = before, 0
        for _, c in cuts:
            removed = int(c["tetrahedra"])
            self.assertGreater(removed, 0, c)
            left -= removed
            self.assertEqual(int(c["remaining"]), left, c)
            self.assertGreater(int(c["topology_version"]), version, c)
            version = int(c["topology_version"])
        self.assertLess(left, before)
        self.assertEqual([f for _, f in self.lines("cut") if f.get("tool") != "hook"], [])

    def test_every_solve_stayed_finite(self):
        failed = [line for line in self.log if "event=tool_solve_failed" in line]
        self.assertEqual(failed, [], "\n".join(failed[:5]))

    def test_the_pliers_held_through_the_cut(self):
        cuts = self.lines("cut", "hook")
        self.assertGreater(len(cuts), 0)
        grasps = self.lines("tool_grasp", "left")
        releases = self.lines("tool_release", "left")
        self.assertEqual(len(grasps), 1, grasps)
        self.assertEqual(len(releases), 1, releases)
        self.assertLess(grasps[0][0], cuts[0][0], "the grasp comes before the first cut")
        self.assertGreater(releases[0][0], cuts[-1][0], "the release comes after the last cut")
        with open(self.json_path) as f:
            summary = json.load(f)
        left = next(t for t in summary["tools"] if t["id"] == "left")
        self.assertEqual(left["events"].get("grasp", 0), 1, left["events"])
        self.assertEqual(left["events"].get("release", 0), 1, left["events"])
        # Tick by tick: while the hook's edge is live, the left tool's answers
        # say it grasps.
        with open(self.csv_path) as f:
            rows = list(csv.DictReader(f))
        hook_live = {r["tick"] for r in rows
                     if r["tool"] == "hook" and float(r["jaw_deg"]) <= GRASP_ANGLE_DEG}
        self.assertGreater(len(hook_live), 1000, "the edge is live for 2 s of the gesture")
        answered = [r for r in rows
                    if r["tool"] == "left" and r["tick"] in hook_live and r["state"]]
        self.assertGreater(len(answered), 0)
        not_grasping = [(r["tick"], r["state"]) for r in answered if r["state"] != "grasping"]
        self.assertEqual(not_grasping, [], f"{len(not_grasping)} of {len(answered)} answers")

    def test_the_hooks_contact_is_one_episode_per_stroke(self):
        # While its edge is live the hook's contact is there every other
        # tick (it cuts through what it touches); its touch and leave events
        # tell contact episodes (docs/tools.md, "One tick"): one stroke, at
        # most a touch and a leave each for the press and the draw, not one
        # pair per millisecond (131 pairs before 2026-12-02).
        with open(self.json_path) as f:
            summary = json.load(f)
        hook = next(t for t in summary["tools"] if t["id"] == "hook")
        self.assertLessEqual(hook["events"].get("touch", 0), 2, hook["events"])
        self.assertLessEqual(hook["events"].get("leave", 0), 2, hook["events"])
        self.assertEqual(len(self.lines("tool_touch", "hook")), hook["events"].get("touch", 0))


if __name__ == "__main__":
    BUILD, SOURCE = (os.path.realpath(a) for a in sys.argv[1:3])
    unittest.main(argv=sys.argv[:1] + sys.argv[3:], verbosity=2)
