#!/usr/bin/python3
"""scripts/session_plots.py: the PNGs it writes and the data they show.

palpate_session_writer_for_tests writes a known session (described in
tests/session_writer_for_tests.cpp), once closed and once killed before
closing. The series the script plots (session_plots.read_series) are checked
against the file's datasets and against the session's definition written out
by hand here; the figures are checked to draw exactly those series (the
latency as a cumulative distribution on a log axis with p50, p99 and max
marked; events of the kinds "ended", unknown names and unnamed numbers with a
style each); the PNGs
are checked to be PNGs of the expected size. Refused files get one line on
stderr, exit code 2 and no PNG; a failed write leaves no PNG.
Usage: session_plots_test.py WRITER SCRIPT
"""
import errno
import os
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import unittest

import h5py
import numpy as np

WRITER = None
SCRIPT = None
plots = None  # the script, imported as a module

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
PLOTS = ["force", "latency", "contacts"]
# Pixel sizes of the PNGs: 10 in × 100 dpi wide; force and contacts 1 + 2.6 in
# per tool (two tools), latency 5 in high. ±1 px: figsize × dpi is rounded.
SIZE = {"force": (1000, 620), "latency": (1000, 500), "contacts": (1000, 620)}
SIZE_TOLERANCE_PX = 1

# Values copied from the file (time, force, counts) are compared exactly; the
# values the script derives (|f|, ns → µs) carry a rounding or two of float64:
# 1e-12 relative is far below anything the plots resolve and far above that.
REL = 1e-12
# Latencies: the writer's steps are 10 ns (0.01 µs); 1e-9 µs absolute tells
# them apart and absorbs the rounding of k·0.01 in float64.
LATENCY_ATOL_US = 1e-9


def left_expected():
    """Tool "left" as tests/session_writer_for_tests.cpp defines it."""
    k = np.arange(1000)
    grasping = ((k >= 500) & (k < 600)) | ((k >= 650) & (k < 700))
    touching = (k >= 200) & (k < 700) & ~grasping
    force = np.zeros((1000, 3))
    force[touching, 2] = 2.0
    force[grasping, 2] = 3.0
    force[550] = [0.0, 3.0, 4.0]
    contacts = np.where(grasping, 4, np.where(touching, 1 + k % 3, 0))
    latency_us = np.where(k < 985, 20.0 + 0.01 * k, 150.0 + 1.0 * (k - 985))
    events = [(0.2, "touch"), (0.5, "grasp"), (0.6, "release"), (0.65, "grasp"),
              (0.7, "release"), (0.7, "leave")]
    return dict(time_s=k * 1e-3, force_n=force, contact_count=contacts, latency_us=latency_us,
                # Nearest rank round(q·(n − 1)): ranks 500 and 989 of k-ordered values.
                p50_us=25.0, p99_us=154.0, max_us=164.0, max_force_n=5.0, events=events)


def right_expected():
    k = np.arange(500)
    touching = (k >= 100) & (k < 200)
    force = np.zeros((500, 3))
    force[touching, 0] = 1.0
    return dict(time_s=k * 2e-3, force_n=force, contact_count=touching.astype(int),
                latency_us=40.0 + 0.02 * k, p50_us=45.0, p99_us=49.88, max_us=49.98,
                max_force_n=1.0,
                events=[(0.2, "touch"), (0.4, "leave")])


EXPECTED = {"left": left_expected(), "right": right_expected()}


def run(*args):
    return subprocess.run(["/usr/bin/python3", SCRIPT, *args], capture_output=True, text=True)


def png_size(path):
    """(width, height) from the IHDR chunk, after checking the signature."""
    with open(path, "rb") as f:
        head = f.read(24)
    assert head[:8] == PNG_MAGIC, f"{path}: not a PNG signature: {head[:8]!r}"
    length, kind = struct.unpack(">I4s", head[8:16])
    assert (length, kind) == (13, b"IHDR"), f"{path}: first chunk {kind!r} of {length} bytes"
    return struct.unpack(">II", head[16:24])


def lines_by_label(ax):
    return {line.get_label(): line for line in ax.get_lines()}


def vertical_line_positions(ax):
    """x of the axvline markers (two points at one x, spanning the axes)."""
    return sorted(float(line.get_xdata()[0]) for line in ax.get_lines()
                  if len(line.get_xdata()) == 2 and line.get_xdata()[0] == line.get_xdata()[1])


def empty_tools(path, tool_ids):
    """Cuts every tick (and contact) of the given tools out of a copy of a
    session: the layout of a session in which they never ticked."""
    with h5py.File(path, "r+") as f:
        for tool_id in tool_ids:
            g = f["tools"][tool_id]
            for name in list(g) + [f"contacts/{n}" for n in g["contacts"]]:
                if isinstance(g[name], h5py.Dataset):
                    g[name].resize(0, axis=0)


def add_events(path, new_names, events):
    """Appends kinds to /events/kind's `names` and events to a copy of a
    session, as a recorder that knows more kinds writes them. events:
    [(time_s, tool index, kind name or a raw kind number)]."""
    with h5py.File(path, "r+") as f:
        kind = f["events/kind"]
        names = [n.decode() if isinstance(n, bytes) else str(n) for n in kind.attrs["names"]]
        names += [n for n in new_names if n not in names]  # a newer recorder may name them already
        kind.attrs["names"] = np.array(names, dtype=h5py.string_dtype())
        n = len(kind)
        columns = {"time_s": [e[0] for e in events], "tool": [e[1] for e in events],
                   "kind": [names.index(e[2]) if isinstance(e[2], str) else e[2] for e in events]}
        for name in f["events"]:
            d = f["events"][name]
            d.resize(n + len(events), axis=0)
            if name in columns:
                d[n:] = columns[name]


class SessionPlots(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.dir = tempfile.TemporaryDirectory()
        # Matplotlib's cache (fonts) in the test's own directory: no message
        # about an unwritable home on stderr, whoever runs the test.
        os.environ["MPLCONFIGDIR"] = os.path.join(cls.dir.name, "mplconfig")
        cls.closed = os.path.join(cls.dir.name, "closed.h5")
        p = subprocess.run([WRITER, cls.closed], capture_output=True, text=True)
        assert p.returncode == 0, p.stderr
        crashed_dir = os.path.join(cls.dir.name, "crashed")
        os.mkdir(crashed_dir)
        crashed = os.path.join(crashed_dir, "crashed.h5")
        p = subprocess.run([WRITER, crashed, "--crash"], capture_output=True, text=True)
        assert p.returncode == -signal.SIGKILL, (p.returncode, p.stderr)
        cls.partial = crashed + ".partial"
        cls.out = os.path.join(cls.dir.name, "plots")
        cls.run_closed = run(cls.closed, "--out", cls.out)
        cls.session = plots.read_series(cls.closed)

    @classmethod
    def tearDownClass(cls):
        cls.dir.cleanup()

    def scratch(self, name):
        """A fresh directory of this test."""
        path = os.path.join(self.dir.name, self.id().rsplit(".", 1)[-1], name)
        os.makedirs(path)
        return path

    # --- the PNGs -------------------------------------------------------------

    def test_the_pngs_are_written_and_their_paths_printed(self):
        p = self.run_closed
        self.assertEqual(p.returncode, 0, p.stderr)
        expected = [os.path.join(self.out, f"closed-{name}.png") for name in PLOTS]
        self.assertEqual(p.stdout.splitlines(), expected)
        # No temporary file left beside them.
        self.assertEqual(sorted(os.listdir(self.out)), sorted(map(os.path.basename, expected)))

    def test_the_pngs_are_pngs_of_the_expected_size_with_something_drawn(self):
        import matplotlib.image
        for name in PLOTS:
            with self.subTest(plot=name):
                path = os.path.join(self.out, f"closed-{name}.png")
                width, height = png_size(path)
                self.assertLessEqual(abs(width - SIZE[name][0]), SIZE_TOLERANCE_PX, width)
                self.assertLessEqual(abs(height - SIZE[name][1]), SIZE_TOLERANCE_PX, height)
                pixels = matplotlib.image.imread(path)  # decodes the whole file
                self.assertEqual(pixels.shape[:2], (height, width))
                # Not a blank page: some pixels are far from the white background.
                self.assertGreater(float((pixels[..., :3] < 0.5).mean()), 0.001)

    # --- the series -----------------------------------------------------------

    def test_the_series_are_the_files_datasets(self):
        with h5py.File(self.closed, "r") as f:
            self.assertEqual([t.id for t in self.session.tools], list(f["tools"].attrs["ids"]))
            kinds = list(f["events/kind"].attrs["names"])
            for index, tool in enumerate(self.session.tools):
                with self.subTest(tool=tool.id):
                    g = f["tools"][tool.id]
                    np.testing.assert_array_equal(tool.time_s, g["time_s"][:])
                    np.testing.assert_array_equal(tool.force_n, g["force"][:])
                    np.testing.assert_allclose(tool.force_magnitude_n,
                                               np.sqrt((g["force"][:] ** 2).sum(axis=1)),
                                               rtol=REL, atol=0)
                    np.testing.assert_array_equal(tool.contact_count, g["contact_count"][:])
                    np.testing.assert_allclose(tool.latency_us, g["compute_ns"][:] / 1000.0,
                                               rtol=REL, atol=0)
                    mine = f["events/tool"][:] == index
                    self.assertEqual(tool.events,
                                     [(float(t), kinds[k]) for t, k in
                                      zip(f["events/time_s"][mine], f["events/kind"][mine])])

    def test_the_series_are_the_sessions_definition(self):
        for tool in self.session.tools:
            e = EXPECTED[tool.id]
            with self.subTest(tool=tool.id):
                np.testing.assert_allclose(tool.time_s, e["time_s"], rtol=REL, atol=0)
                np.testing.assert_allclose(tool.force_n, e["force_n"], rtol=REL, atol=0)
                np.testing.assert_allclose(tool.force_magnitude_n,
                                           np.linalg.norm(e["force_n"], axis=1), rtol=REL, atol=0)
                self.assertAlmostEqual(float(tool.force_magnitude_n.max()), e["max_force_n"],
                                       delta=REL * e["max_force_n"])
                np.testing.assert_array_equal(tool.contact_count, e["contact_count"])
                np.testing.assert_allclose(tool.latency_us, e["latency_us"], rtol=0,
                                           atol=LATENCY_ATOL_US)
                self.assertAlmostEqual(tool.latency_p50_us, e["p50_us"], delta=LATENCY_ATOL_US)
                self.assertAlmostEqual(tool.latency_p99_us, e["p99_us"], delta=LATENCY_ATOL_US)
                self.assertEqual([k for _, k in tool.events], [k for _, k in e["events"]])
                np.testing.assert_allclose([t for t, _ in tool.events],
                                           [t for t, _ in e["events"]], rtol=REL, atol=0)

    def test_nearest_rank_is_the_daemons_definition(self):
        # statistics.hpp: the element at rank round(q·(n − 1)), 0 for none.
        self.assertEqual(plots.nearest_rank(np.array([]), 0.5), 0.0)
        self.assertEqual(plots.nearest_rank(np.array([3.0, 1.0, 2.0, 4.0]), 0.5), 3.0)  # rank 2
        self.assertEqual(plots.nearest_rank(np.array([3.0, 1.0, 2.0, 4.0]), 0.99), 4.0)
        self.assertEqual(plots.nearest_rank(np.arange(101.0), 0.99), 99.0)

    def test_the_latency_cdf_is_every_tick_sorted_with_its_rank(self):
        for tool in self.session.tools:
            with self.subTest(tool=tool.id):
                x, y = plots.latency_cdf(tool.latency_us)
                expected = np.sort(EXPECTED[tool.id]["latency_us"])
                np.testing.assert_allclose(x, expected, rtol=0, atol=LATENCY_ATOL_US)
                n = len(expected)
                np.testing.assert_allclose(y, np.arange(1, n + 1) / n, rtol=REL, atol=0)
                # The CDF at p50 and p99 reaches those fractions (nearest rank
                # round(q·(n − 1)) is the element at index q·(n − 1), 0-based,
                # so the share at or below it is at least q·(n − 1)/n + 1/n ≥ q
                # for q ≤ 1).
                for q, key in ((0.5, "p50_us"), (0.99, "p99_us")):
                    self.assertGreaterEqual(plots.fraction_at_or_below(x, EXPECTED[tool.id][key]), q)
                self.assertAlmostEqual(tool.latency_max_us, EXPECTED[tool.id]["max_us"],
                                       delta=LATENCY_ATOL_US)
                self.assertEqual(plots.fraction_at_or_below(x, tool.latency_max_us), 1.0)

    def test_the_latency_axis_spans_every_tick_and_clips_zero(self):
        lo, hi = plots.latency_axis_limits(self.session)
        # The fastest tick is left's 20 µs, the slowest left's 164 µs.
        self.assertAlmostEqual(lo, 20.0 / plots.LATENCY_MARGIN, delta=LATENCY_ATOL_US)
        self.assertAlmostEqual(hi, 164.0 * plots.LATENCY_MARGIN, delta=LATENCY_ATOL_US)
        session = plots.read_series(self.closed)
        session.tools[1].latency_us[:3] = 0.0  # below the clock's resolution
        lo, _ = plots.latency_axis_limits(session)
        self.assertGreater(lo, 0.0)
        self.assertLessEqual(lo, 0.1)

    # --- the figures draw the series -------------------------------------------

    def test_the_force_figure_draws_the_force_and_events_of_each_tool(self):
        fig = plots.figures(self.session)["force"]
        self.assertEqual(len(fig.axes), 2)
        for ax, tool in zip(fig.axes, self.session.tools):
            with self.subTest(tool=tool.id):
                self.assertIn(tool.id, ax.get_title())
                self.assertIn("(N)", ax.get_ylabel())
                lines = lines_by_label(ax)
                np.testing.assert_array_equal(lines["|f|"].get_xdata(), tool.time_s)
                np.testing.assert_array_equal(lines["|f|"].get_ydata(), tool.force_magnitude_n)
                for j, axis in enumerate("xyz"):
                    np.testing.assert_array_equal(lines[f"f{axis}"].get_ydata(),
                                                  tool.force_n[:, j])
                self.assertEqual(lines["|f|"].get_drawstyle(), "steps-post")
                expected = EXPECTED[tool.id]["events"]
                np.testing.assert_allclose(vertical_line_positions(ax),
                                           sorted(t for t, _ in expected), rtol=REL, atol=0)
                legend = [t.get_text() for t in ax.get_legend().get_texts()]
                self.assertEqual({t[len("event: "):] for t in legend if t.startswith("event: ")},
                                 {k for _, k in expected})
        self.assertIn("(s)", fig.axes[-1].get_xlabel())
        self.assertNotIn("INCOMPLETE", fig._suptitle.get_text())

    def test_the_force_figure_draws_what_the_device_rendered_on_the_session_clock(self):
        # left's device rendered 4 steps per tick over ticks 200-299, each
        # tick's first at its pose's send time: on the session clock (the
        # ticks' time_s − send_time_ns is −1 s exactly) k ms + j·0.25 ms.
        fig = plots.figures(self.session)["force"]
        label = "|f| rendered by the device"
        k, j = np.meshgrid(np.arange(200, 300), np.arange(4), indexing="ij")
        left = lines_by_label(fig.axes[0])[label]
        np.testing.assert_allclose(left.get_xdata(), (k * 1e-3 + j * 2.5e-4).ravel(), rtol=0,
                                   atol=1e-12)
        np.testing.assert_allclose(left.get_ydata(), (2 + 0.1 * j).ravel(), rtol=REL, atol=0)
        self.assertNotIn(label, lines_by_label(fig.axes[1]), "right's device reported nothing")

    def test_the_contacts_figure_draws_the_contact_counts(self):
        fig = plots.figures(self.session)["contacts"]
        self.assertEqual(len(fig.axes), 2)
        for ax, tool in zip(fig.axes, self.session.tools):
            with self.subTest(tool=tool.id):
                line = lines_by_label(ax)["loaded vertices"]
                np.testing.assert_array_equal(line.get_xdata(), tool.time_s)
                np.testing.assert_array_equal(line.get_ydata(), tool.contact_count)
                # Named for what it counts, vertices, not contact points (issue 35).
                self.assertIn(f"at most {int(EXPECTED[tool.id]['contact_count'].max())} loaded "
                              "vertices per tick", ax.get_title())

    def test_the_latency_figure_draws_the_cdfs_and_marks_p50_p99_max(self):
        fig = plots.figures(self.session)["latency"]
        (ax,) = fig.axes
        self.assertEqual(ax.get_xscale(), "log")
        self.assertIn("(µs, log scale)", ax.get_xlabel())
        self.assertIn("cumulative distribution", fig._suptitle.get_text())
        self.assertEqual(ax.get_ylim(), (0.0, 1.02))
        lo, hi = ax.get_xlim()
        lines = lines_by_label(ax)
        for tool in self.session.tools:
            with self.subTest(tool=tool.id):
                e = EXPECTED[tool.id]
                cdf = lines[f"tool {tool.id} ({len(tool.time_s)} ticks)"]
                self.assertEqual(cdf.get_drawstyle(), "steps-post")
                x, y = plots.latency_cdf(tool.latency_us)
                np.testing.assert_array_equal(cdf.get_xdata(), x)
                np.testing.assert_array_equal(cdf.get_ydata(), y)
                self.assertLessEqual(lo, x[0])
                self.assertGreaterEqual(hi, x[-1])
                for q in ("p50", "p99", "max"):
                    value = e[f"{q}_us"]
                    marker = lines[f"tool {tool.id} {q} {value:.1f} µs"]
                    at = float(marker.get_xdata()[0])
                    self.assertAlmostEqual(at, value, delta=LATENCY_ATOL_US)
                    # On the curve: the CDF's value at that latency.
                    self.assertEqual(float(marker.get_ydata()[0]), plots.fraction_at_or_below(x, at))
                # A dotted vertical guide at each of the three.
                guides = vertical_line_positions(ax)
                for q in ("p50", "p99", "max"):
                    self.assertTrue(any(abs(g - e[f"{q}_us"]) <= LATENCY_ATOL_US for g in guides),
                                    (q, guides))

    def test_the_latency_y_axis_is_the_linear_share_of_ticks(self):
        fig = plots.figures(self.session)["latency"]
        self.assertEqual(fig.axes[0].get_yscale(), "linear")
        self.assertIn("fraction of ticks", fig.axes[0].get_ylabel())

    # --- other sessions -------------------------------------------------------

    def test_a_crashed_recording_is_plotted_next_to_it_as_partial(self):
        p = run(self.partial)  # no --out: beside the file
        self.assertEqual(p.returncode, 0, p.stderr)
        where = os.path.dirname(self.partial)
        expected = [os.path.join(where, f"crashed-partial-{name}.png") for name in PLOTS]
        self.assertEqual(p.stdout.splitlines(), expected)
        for path in expected:
            self.assertEqual(png_size(path)[0], SIZE["force"][0])
        # Flushed before the kill: every tick is there.
        session = plots.read_series(self.partial)
        self.assertFalse(session.complete)
        for tool, closed in zip(session.tools, self.session.tools):
            np.testing.assert_array_equal(tool.force_n, closed.force_n)
            np.testing.assert_array_equal(tool.contact_count, closed.contact_count)
        self.assertIn("INCOMPLETE", plots.figures(session)["force"]._suptitle.get_text())

    def test_a_tool_without_ticks_is_plotted_as_such(self):
        path = os.path.join(self.scratch("in"), "one-tool.h5")
        shutil.copy(self.closed, path)
        empty_tools(path, ["right"])
        out = os.path.join(os.path.dirname(path), "plots")
        p = run(path, "--out", out)
        self.assertEqual(p.returncode, 0, p.stderr)
        self.assertEqual(len(p.stdout.splitlines()), 3)
        session = plots.read_series(path)
        self.assertEqual([len(t.time_s) for t in session.tools], [1000, 0])
        fig = plots.figures(session)["force"]
        self.assertEqual(len(fig.axes[1].get_lines()), 0)
        self.assertIn("no tick recorded", [t.get_text() for t in fig.axes[1].texts])

    def test_ended_and_unknown_event_kinds_are_drawn(self):
        path = os.path.join(self.scratch("in"), "ended.h5")
        shutil.copy(self.closed, path)
        add_events(path, ["ended", "from-the-future"],
                   [(0.90, 1, "ended"), (0.95, 1, "from-the-future"), (0.97, 1, 42)])
        out = os.path.join(os.path.dirname(path), "plots")
        p = run(path, "--out", out)
        self.assertEqual(p.returncode, 0, p.stderr)
        self.assertEqual(len(p.stdout.splitlines()), 3)
        session = plots.read_series(path)
        right = session.tools[1]
        self.assertEqual([k for _, k in right.events],
                         ["touch", "leave", "ended", "from-the-future", "kind 42"])
        for name in ("force", "contacts"):
            with self.subTest(plot=name):
                ax = plots.figures(session)[name].axes[1]
                styles = {line.get_label(): (line.get_color(), line.get_linestyle())
                          for line in ax.get_lines()}
                # "ended" has a style of its own, neither leave's nor the watchdog's.
                ended = styles["event: ended"]
                self.assertEqual(ended, (plots.EVENT_STYLE["ended"][0], "--"))
                self.assertNotEqual(ended, styles["event: leave"])
                self.assertNotEqual(ended, plots.EVENT_STYLE["watchdog"])
                grey = (plots.UNKNOWN_EVENT_STYLE[0], "-.")
                self.assertEqual(styles["event: from-the-future"], grey)
                self.assertEqual(styles["event: kind 42"], grey)
                legend = [t.get_text() for t in ax.get_legend().get_texts()]
                self.assertIn("event: ended", legend)
                np.testing.assert_allclose(vertical_line_positions(ax), [0.2, 0.4, 0.9, 0.95, 0.97],
                                           rtol=REL, atol=0)

    # --- refusals and failures --------------------------------------------------

    def check_refused(self, path, fragment):
        """Refused with and without --out: one line, exit code 2, no PNG (and
        no output directory)."""
        out = os.path.join(self.dir.name, "refused-out")
        for args in ([path, "--out", out], [path]):
            with self.subTest(args=args):
                p = run(*args)
                self.assertEqual(p.returncode, 2, p.stdout + p.stderr)
                self.assertEqual(p.stdout, "")
                self.assertEqual(len(p.stderr.splitlines()), 1, p.stderr)
                self.assertTrue(p.stderr.startswith("session_plots: error: "), p.stderr)
                self.assertIn(path, p.stderr)
                self.assertIn(fragment, p.stderr)
                self.assertFalse(os.path.exists(out))
                where = os.path.dirname(path)
                if os.path.isdir(where):
                    self.assertEqual([n for n in os.listdir(where) if ".png" in n], [])

    def test_missing_file(self):
        self.check_refused(os.path.join(self.scratch("in"), "nothing.h5"), "no such file")

    def test_not_hdf5(self):
        path = os.path.join(self.scratch("in"), "notes.h5")
        with open(path, "w") as f:
            f.write("not a recording\n")
        self.check_refused(path, "not an HDF5 file")

    def test_not_a_session_file(self):
        path = os.path.join(self.scratch("in"), "organ.h5")
        with h5py.File(path, "w") as f:
            f.attrs["format"] = "palpate-compliance"
        self.check_refused(path, "a 'palpate-compliance' file, not a palpate session")

    def test_wrong_format_version(self):
        path = os.path.join(self.scratch("in"), "future.h5")
        shutil.copy(self.closed, path)
        with h5py.File(path, "r+") as f:
            f.attrs["format_version"] = np.int32(2)
        self.check_refused(path, "format_version 2")

    def test_empty_session(self):
        path = os.path.join(self.scratch("in"), "empty.h5")
        shutil.copy(self.closed, path)
        empty_tools(path, ["left", "right"])
        self.check_refused(path, "an empty session")

    def test_damaged_session(self):
        path = os.path.join(self.scratch("in"), "damaged.h5")
        shutil.copy(self.closed, path)
        with h5py.File(path, "r+") as f:
            f["tools/right/contact_count"].resize(10, axis=0)
        self.check_refused(path, "tool right: tick datasets of different lengths")

    def test_an_output_directory_that_cannot_be_made(self):
        blocker = os.path.join(self.scratch("in"), "a-file")
        with open(blocker, "w") as f:
            f.write("x\n")
        p = run(self.closed, "--out", blocker)
        self.assertEqual(p.returncode, 1, p.stdout + p.stderr)
        self.assertEqual(p.stdout, "")
        self.assertEqual(len(p.stderr.splitlines()), 1, p.stderr)
        self.assertTrue(p.stderr.startswith("session_plots: error: cannot write the PNGs in "),
                        p.stderr)

    def test_a_failed_write_leaves_no_png_and_the_old_ones_intact(self):
        class DiskFull:
            def savefig(self, out, format):
                out.write(PNG_MAGIC)  # a partial PNG under the temporary name
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

        out = self.scratch("out")
        old = os.path.join(out, "s-force.png")
        with open(old, "wb") as f:
            f.write(b"the previous plot")
        figs = {"force": plots.force_figure(self.session), "latency": DiskFull()}
        with self.assertRaises(OSError):
            plots.write_pngs(figs, out, "s")
        self.assertEqual(os.listdir(out), ["s-force.png"])
        with open(old, "rb") as f:
            self.assertEqual(f.read(), b"the previous plot")


if __name__ == "__main__":
    WRITER, SCRIPT = sys.argv[1], sys.argv[2]
    sys.dont_write_bytecode = True  # no __pycache__ in the source tree
    sys.path.insert(0, os.path.dirname(os.path.abspath(SCRIPT)))
    import session_plots as plots  # noqa: E402
    unittest.main(argv=sys.argv[:1], verbosity=2)
