"""scripts/feel_trace_plots.py on the press reference against a copy with one
force moved by a known amount: it must name that gesture, that |ΔF| and that
time, and write a PNG (docs/tools.md, "The feel under regression tests").

Usage: feel_trace_plots_test.py SOURCE_DIR
"""

import os
import shutil
import subprocess
import sys
import tempfile
import unittest

SOURCE = sys.argv.pop(1) if len(sys.argv) > 1 else "."
SCRIPT = os.path.join(SOURCE, "scripts", "feel_trace_plots.py")
REFERENCE = os.path.join(SOURCE, "tests", "feel", "reference", "press.csv")


class FeelTracePlots(unittest.TestCase):
    def test_names_the_largest_difference(self):
        with tempfile.TemporaryDirectory() as work:
            old, new, out = (os.path.join(work, d) for d in ("old", "new", "plots"))
            os.makedirs(old)
            os.makedirs(new)
            shutil.copy(REFERENCE, old)
            with open(REFERENCE) as f:
                lines = f.read().splitlines()
            # The row of tick 1000 (pressed, held): fz moved by 0.25 N.
            for i, line in enumerate(lines):
                cells = line.split(",")
                if cells[0] == "1000":
                    cells[5] = repr(float(cells[5]) + 0.25)
                    lines[i] = ",".join(cells)
                    break
            else:
                self.fail("press.csv has no row for tick 1000")
            with open(os.path.join(new, "press.csv"), "w") as f:
                f.write("\n".join(lines) + "\n")
            run = subprocess.run(["/usr/bin/python3", SCRIPT, old, new, out],
                                 capture_output=True, text=True, check=True)
            self.assertIn("press", run.stdout)
            self.assertIn("max |ΔF| 0.25 N at 1.000 s (left)", run.stdout)
            with open(os.path.join(out, "press.png"), "rb") as f:
                self.assertEqual(f.read(8), b"\x89PNG\r\n\x1a\n")

    def test_usage(self):
        run = subprocess.run(["/usr/bin/python3", SCRIPT], capture_output=True, text=True)
        self.assertEqual(run.returncode, 2)
        self.assertIn("Usage:", run.stderr)


if __name__ == "__main__":
    unittest.main()
