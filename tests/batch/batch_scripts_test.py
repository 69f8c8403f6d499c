"""Batch precomputation end to end through the command line and the scripts
(docs/precompute.md, "Batch precomputation"):

- scripts/precompute-local.sh with 3 shards gives the file of a single run,
  bit for bit (G and content_sha256), and removes its shard files;
- scripts/precompute-array.slurm submits an array of shards and a dependent
  merge: run here under a stand-in `sbatch` that runs each job at once with
  the variables Slurm sets (the real scheduler is not on this machine);
- a shard SIGKILLed halfway through its solves (PALPATE_PRECOMPUTE_STOP_AT=
  solves@half stops it there, deterministically) keeps its checkpoint, and
  the same command resumes it and gives the same file;
- merge of mismatched shards exits 2 with one clear line and writes nothing.

Usage: batch_scripts_test.py PALPATE_PRECOMPUTE SCRIPTS_DIR
"""

import glob
import os
import signal
import stat
import subprocess
import sys
import tempfile
import unittest

import h5py
import numpy as np

PRECOMPUTE = sys.argv.pop(1)
SCRIPTS = sys.argv.pop(1)

# Slurm's sbatch, for the test only: runs the batch script at once, once per
# array task, with the variables Slurm sets; --parsable prints a job id.
FAKE_SBATCH = r"""#!/usr/bin/python3
import os, subprocess, sys
args = sys.argv[1:]
array = None
while args and args[0].startswith("--"):
    if args[0].startswith("--array="):
        array = args[0].split("=", 1)[1]
    args.pop(0)
log = os.environ["FAKE_SBATCH_LOG"]
with open(log, "a") as f:
    f.write(" ".join(sys.argv[1:]) + "\n")
tasks = [None]
if array:
    first, last = map(int, array.split("-"))
    tasks = list(range(first, last + 1))
for t in tasks:
    env = dict(os.environ, SLURM_JOB_ID="42")
    if t is not None:
        env.update(SLURM_ARRAY_TASK_ID=str(t), SLURM_ARRAY_TASK_COUNT=str(len(tasks)))
    r = subprocess.run(args, env=env)
    if r.returncode != 0:
        sys.exit(r.returncode)
print("42")
"""


def read(path):
    with h5py.File(path) as f:
        return f["/compliance/G"][()], f.attrs["content_sha256"]


class BatchScripts(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.TemporaryDirectory(dir="/dev/shm" if os.path.isdir("/dev/shm") else None)
        cls.dir = cls.tmp.name
        cls.mesh = os.path.join(cls.dir, "organ.msh")
        subprocess.run([PRECOMPUTE, "make-sample", "-o", cls.mesh, "--size", "0.025", "-q"], check=True)
        cls.args = ["--mesh", cls.mesh, "-E", "85e3", "--nu", "0.45", "--fix-sphere", "-0.03", "0", "0.04",
                    "0.03", "--block-columns", "16", "--no-xdmf"]
        cls.single = os.path.join(cls.dir, "single.h5")
        subprocess.run([PRECOMPUTE, *cls.args, "-o", cls.single, "-q"], check=True)
        cls.G, cls.digest = read(cls.single)

    @classmethod
    def tearDownClass(cls):
        cls.tmp.cleanup()

    def env(self):
        return dict(os.environ, PALPATE_PRECOMPUTE=PRECOMPUTE)

    def assert_same_as_single(self, path):
        G, digest = read(path)
        self.assertEqual(digest, self.digest)
        self.assertTrue(np.array_equal(G, self.G))
        self.assertEqual(G.tobytes(), self.G.tobytes())

    def test_local_shards_equal_a_single_run(self):
        out = os.path.join(self.dir, "local.h5")
        r = subprocess.run([os.path.join(SCRIPTS, "precompute-local.sh"), "3", out, *self.args],
                           env=self.env(), capture_output=True, text=True)
        self.assertEqual(r.returncode, 0, r.stdout + r.stderr)
        for k in range(3):
            self.assertIn(f"[shard {k}/3] palpate-precompute: info: shard: columns", r.stdout)
        self.assert_same_as_single(out)
        self.assertEqual(glob.glob(os.path.join(self.dir, "local.part-*")), [])
        self.assertEqual(glob.glob(os.path.join(self.dir, ".local*")), [])

    def test_slurm_array_then_merge(self):
        fake = os.path.join(self.dir, "sbatch")
        with open(fake, "w") as f:
            f.write(FAKE_SBATCH)
        os.chmod(fake, os.stat(fake).st_mode | stat.S_IEXEC)
        log = os.path.join(self.dir, "sbatch.log")
        out = os.path.join(self.dir, "slurm.h5")
        r = subprocess.run([os.path.join(SCRIPTS, "precompute-array.slurm"), "4", out, *self.args, "-q"],
                           env=dict(self.env(), SBATCH=fake, FAKE_SBATCH_LOG=log,
                                    PALPATE_SBATCH_OPTIONS="--partition=cpu"),
                           capture_output=True, text=True)
        self.assertEqual(r.returncode, 0, r.stdout + r.stderr)
        with open(log) as f:
            calls = f.read().splitlines()
        self.assertEqual(len(calls), 2, calls)
        self.assertIn("--array=0-3", calls[0])
        self.assertIn("--partition=cpu", calls[0])
        self.assertIn("--dependency=afterok:42", calls[1])
        self.assertIn("merge: job 42 after they all succeed", r.stdout)
        self.assert_same_as_single(out)
        self.assertEqual(glob.glob(os.path.join(self.dir, "slurm.part-*")), [])

    def test_a_shard_killed_halfway_resumes(self):
        out = os.path.join(self.dir, "killed.h5")
        shard = [PRECOMPUTE, *self.args, "--shard", "1/2", "-o", out]
        p = subprocess.Popen(shard + ["--phases"], stderr=subprocess.DEVNULL,
                             env=dict(os.environ, PALPATE_PRECOMPUTE_STOP_AT="solves@half"))
        try:
            _, status = os.waitpid(p.pid, os.WUNTRACED)
            self.assertTrue(os.WIFSTOPPED(status))
            checkpoints = glob.glob(os.path.join(self.dir, ".killed.part-*.h5.checkpoint"))
            self.assertEqual(len(checkpoints), 1, checkpoints)
            p.kill()
            self.assertEqual(p.wait(), -signal.SIGKILL)
        finally:
            if p.poll() is None:
                p.kill()
                p.wait()
        self.assertTrue(os.path.exists(checkpoints[0]))
        self.assertEqual(glob.glob(os.path.join(self.dir, "killed.part-*")), [])
        r = subprocess.run(shard, capture_output=True, text=True)
        self.assertEqual(r.returncode, 0, r.stderr)
        self.assertRegex(r.stderr, r"info: resuming .*\.checkpoint: [1-9]\d* of \d+ blocks already complete")
        self.assertFalse(os.path.exists(checkpoints[0]))
        subprocess.run([PRECOMPUTE, *self.args, "--shard", "0/2", "-o", out, "-q"], check=True)
        parts = sorted(glob.glob(os.path.join(self.dir, "killed.part-*.h5")))
        self.assertEqual(len(parts), 2)
        subprocess.run([PRECOMPUTE, "merge", "-o", out, "--no-xdmf", "-q", *parts], check=True)
        self.assert_same_as_single(out)

    def test_mismatched_shards_exit_2_and_write_nothing(self):
        out = os.path.join(self.dir, "mixed.h5")
        for shard in ("0/2", "1/2"):
            subprocess.run([PRECOMPUTE, *self.args, "--shard", shard, "-o", out, "-q"], check=True)
        other = os.path.join(self.dir, "other.h5")
        stiffer = ["170e3" if a == "85e3" else a for a in self.args]
        subprocess.run([PRECOMPUTE, *stiffer, "--shard", "1/2", "-o", other, "-q"], check=True)
        mine = sorted(glob.glob(os.path.join(self.dir, "mixed.part-*.h5")))
        theirs = glob.glob(os.path.join(self.dir, "other.part-*.h5"))
        for shards, message in [([mine[0], theirs[0]], "come from different inputs"),
                                ([mine[0]], "are in no shard"),
                                ([mine[0], mine[0], mine[1]], "both hold columns")]:
            with self.subTest(message=message):
                r = subprocess.run([PRECOMPUTE, "merge", "-o", out, *shards], capture_output=True, text=True)
                self.assertEqual(r.returncode, 2, r.stderr)
                self.assertIn(message, r.stderr)
                self.assertEqual(len(r.stderr.strip().splitlines()), 1, r.stderr)
                self.assertFalse(os.path.exists(out))


if __name__ == "__main__":
    unittest.main(verbosity=2)
