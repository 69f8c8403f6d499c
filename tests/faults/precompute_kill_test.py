"""palpate-precompute killed (SIGKILL: no handler runs) at every phase
(docs/faults.md, "palpate-precompute killed"): nothing at the output path
nor at its XDMF sidecar's (or, when an earlier file was there, that file
unchanged, byte for byte); the next run of the same output removes the
temporary file the killed one left, says so, and writes a valid file.

The kill point is deterministic: PALPATE_PRECOMPUTE_STOP_AT=<phase> makes
palpate-precompute stop itself (SIGSTOP) as the phase starts, <phase>@half
halfway through it (precompute/main.cpp); the test waits for the stop, checks
the phase's line on stderr, then SIGKILLs it.

Usage: precompute_kill_test.py PALPATE_PRECOMPUTE
"""

import glob
import hashlib
import os
import signal
import subprocess
import sys
import tempfile
import unittest

import h5py

PRECOMPUTE = sys.argv.pop(1)
PHASES = ["read mesh", "assemble K", "condensation", "solves", "checks", "write file"]
HALFWAY = ["write file@half"]  # G half written to the temporary file


def sha256(path):
    with open(path, "rb") as f:
        return hashlib.sha256(f.read()).hexdigest()


class KilledAtEveryPhase(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        # tmpfs when there is one: the runs' fsyncs cost nothing there.
        cls.dir = tempfile.TemporaryDirectory(dir="/dev/shm" if os.path.isdir("/dev/shm") else None)
        cls.mesh = os.path.join(cls.dir.name, "organ.msh")
        subprocess.run([PRECOMPUTE, "make-sample", "-o", cls.mesh, "--size", "0.03", "-q"], check=True)

    @classmethod
    def tearDownClass(cls):
        cls.dir.cleanup()

    def args(self, out, young="85e3"):
        return [PRECOMPUTE, "--mesh", self.mesh, "-E", young, "--nu", "0.45", "--fix-sphere", "-0.03",
                "0", "0.04", "0.03", "-o", out]

    def kill_at(self, stop_at, out, young="85e3"):
        """Runs until the stop point, checks what is on disk while stopped, SIGKILLs it."""
        err = os.path.join(self.dir.name, "stderr.txt")
        with open(err, "w") as stderr:
            p = subprocess.Popen(self.args(out, young) + ["--phases"], stderr=stderr,
                                 stdout=subprocess.DEVNULL,
                                 env=dict(os.environ, PALPATE_PRECOMPUTE_STOP_AT=stop_at))
        try:
            _, status = os.waitpid(p.pid, os.WUNTRACED)
            self.assertTrue(os.WIFSTOPPED(status), f"{stop_at}: not stopped (status {status})")
            phase = stop_at.split("@")[0]
            with open(err) as f:
                lines = f.read().splitlines()
            self.assertEqual(lines[-1], f"palpate-precompute: phase: {phase}", lines)
            temps = glob.glob(os.path.join(self.dir.name, ".*.tmp-*"))
            if stop_at == "write file@half":
                # Half of G is in the temporary file, beside the output.
                self.assertEqual([os.path.basename(t) for t in temps],
                                 [f".{os.path.basename(out)}.tmp-{p.pid}"])
                self.assertGreater(os.path.getsize(temps[0]), 0)
            else:
                self.assertEqual(temps, [], stop_at)
            os.kill(p.pid, signal.SIGKILL)
            _, status = os.waitpid(p.pid, 0)
            self.assertTrue(os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGKILL)
        finally:
            if p.poll() is None and p.returncode is None:
                try:
                    os.kill(p.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
        return p.pid

    def rerun(self, out, killed_pid):
        r = subprocess.run(self.args(out), capture_output=True, text=True)
        self.assertEqual(r.returncode, 0, r.stderr)
        temp = os.path.join(self.dir.name, f".{os.path.basename(out)}.tmp-{killed_pid}")
        left = os.path.exists(temp)
        self.assertEqual(glob.glob(os.path.join(self.dir.name, ".*.tmp-*")), [])
        return r.stderr, temp, left

    def check_valid(self, out):
        with h5py.File(out) as f:
            self.assertEqual(f.attrs["format"], "palpate-compliance")
            n = f["/compliance/vertex_ids"].shape[0]
            self.assertEqual(f["/compliance/G"].shape, (3 * n, 3 * n))
            self.assertRegex(f.attrs["content_sha256"], r"^sha256:[0-9a-f]{64}$")
        self.assertTrue(os.path.exists(out[:-3] + ".xdmf"))

    def test_nothing_at_the_output_path_then_a_rerun_succeeds(self):
        # One kill per phase start, and one halfway through writing the file;
        # then one run (each costs 0.6 s of start-up) that cleans up and writes it.
        out = os.path.join(self.dir.name, "fresh.h5")
        pids = {}
        for stop_at in PHASES + HALFWAY:
            with self.subTest(stop_at=stop_at):
                pids[stop_at] = self.kill_at(stop_at, out)
                self.assertFalse(os.path.exists(out), stop_at)
                self.assertFalse(os.path.exists(out[:-3] + ".xdmf"), stop_at)
        stderr, temp, _ = self.rerun(out, pids["write file@half"])
        self.assertEqual(stderr.count("removed"), 1, stderr)
        self.assertIn(f"palpate-precompute: warning: removed {temp}, left by an interrupted run "
                      f"(process {pids['write file@half']} is gone)", stderr)
        self.check_valid(out)

    def test_a_kill_while_replacing_a_file_leaves_the_old_one_whole(self):
        out = os.path.join(self.dir.name, "kept.h5")
        subprocess.run(self.args(out) + ["-q"], check=True)
        before = sha256(out), sha256(out[:-3] + ".xdmf")
        for stop_at in ["solves", "write file@half"]:
            with self.subTest(stop_at=stop_at):
                self.kill_at(stop_at, out, young="170e3")
                self.assertEqual((sha256(out), sha256(out[:-3] + ".xdmf")), before, stop_at)
        stderr, _, _ = self.rerun(out, 0)
        self.check_valid(out)


if __name__ == "__main__":
    unittest.main()
