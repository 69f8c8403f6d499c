#!/usr/bin/python3
"""Plots of a palpate session recording, as PNG files.

Reads a file written by palpated's session recorder (docs/session-recording.md,
section "Plots") and writes three PNGs:
  <stem>-force.png     per tool, the force sent to the device (|f| and x, y, z),
                       and what the device rendered at its own rate when recorded
                       against time, the tool's events (touch, grasp...) marked;
  <stem>-latency.png   cumulative distribution of the daemon's compute latency
                       per tick (pose taken -> feedback written, `compute_ns`),
                       µs on a log axis, per tool, with its p50, p99 and max
                       marked;
  <stem>-contacts.png  per tool, the vertices carrying contact force per tick against
                       time, events marked (a contact point on a triangle loads up to
                       its 3 vertices: usually more than palpate-pliers' contact points).
<stem> is the file name without ".h5" ("-partial" appended for a "<file>.partial"
left by a crash, which is plotted up to its last flush). Each PNG is written
under a temporary name in the output directory and renamed into place.

Usage: session_plots.py FILE [--out DIR]      (DIR: default the file's directory)
Prints the paths written, one per line.
Exit codes: 0; 2 for a missing, unreadable, locked, foreign or empty session
file; 1 if the PNGs cannot be written. Errors are one line on stderr, and
leave no PNG behind.
"""
import argparse
import os
import signal
import sys
import tempfile
from dataclasses import dataclass, field

import numpy as np

from session_report import Refused, open_session, text  # scripts/, beside this file

PROGRAM = "session_plots"
US_PER_NS = 1e-3  # compute_ns is stored in ns, plotted in µs

# Event kinds (the /events/kind `names`) as colour and line style; an unknown
# name (a newer recorder) is drawn with UNKNOWN_EVENT_STYLE and its name in
# the legend. "ended" (the client ended the session normally) is dashed like
# the watchdog, whose normal counterpart it is, and green like leave.
EVENT_STYLE = {
    "touch": ("tab:green", "-"),
    "leave": ("tab:green", ":"),
    "grasp": ("tab:red", "-"),
    "release": ("tab:red", ":"),
    "watchdog": ("black", "--"),
    "resumed": ("black", ":"),
    "ended": ("darkgreen", "--"),
}
UNKNOWN_EVENT_STYLE = ("grey", "-.")
FORCE_COMPONENTS = (("x", "tab:blue"), ("y", "tab:orange"), ("z", "tab:purple"))
TOOL_COLORS = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown")
# Figure sizes, inches at DPI: force and contacts 1 + 2.6 per tool high, latency 5.
WIDTH_IN, TITLE_HEIGHT_IN, ROW_HEIGHT_IN, LATENCY_HEIGHT_IN, DPI = 10.0, 1.0, 2.6, 5.0, 100
# The latency axis reaches this factor beyond the fastest and slowest ticks.
LATENCY_MARGIN = 1.25


def new_figure(width_in, height_in):
    """An empty figure drawn by Agg (files only, never a display).

    Matplotlib is imported here, once there is something to plot: a refused
    file costs neither its import time nor its first-run font cache messages."""
    import matplotlib
    matplotlib.use("Agg")
    # Long sessions (1 kHz for minutes) make paths longer than Agg draws at once.
    matplotlib.rcParams["agg.path.chunksize"] = 10000
    from matplotlib.figure import Figure
    return Figure(figsize=(width_in, height_in), dpi=DPI, layout="constrained")


def nearest_rank(values, q):
    """The q-quantile (q in [0, 1]) of values: the sorted element at rank
    round(q·(n − 1)), as palpated's heartbeat reports its latencies
    (lib/core/include/palpate/core/statistics.hpp). 0 for no values."""
    if len(values) == 0:
        return 0.0
    s = np.sort(values)
    return float(s[int(q * (len(s) - 1) + 0.5)])


@dataclass
class ToolSeries:
    """What the plots show of one tool; row k of each array is tick k."""
    id: str
    time_s: np.ndarray             # [n] s, session clock
    force_n: np.ndarray            # [n, 3] N, sent to the device, model frame
    force_magnitude_n: np.ndarray  # [n] N, Euclidean norm of force_n
    contact_count: np.ndarray      # [n] contacts of the tick
    latency_us: np.ndarray         # [n] µs, compute_ns converted
    latency_p50_us: float
    latency_p99_us: float
    latency_max_us: float
    events: list = field(default_factory=list)  # [(time_s, kind name)] of this tool
    # What the device rendered (the rendered group; empty without it), on the
    # session clock: its client-clock times shifted by the median of the
    # ticks' time_s − send_time_ns (the pose's one-way trip, tens of µs).
    rendered_time_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    rendered_magnitude_n: np.ndarray = field(default_factory=lambda: np.zeros(0))


@dataclass
class SessionSeries:
    file: str
    model_id: str
    complete: bool      # closed normally (False: a crashed "<file>.partial")
    tools: list         # [ToolSeries] in tool index order


def read_series(path):
    """The series the plots show, from the datasets of the session file at
    path. Raises Refused (one-line message) for a file that cannot be plotted,
    including a session without a single tick."""
    with open_session(path) as f:
        try:
            ids = [text(i) for i in f["tools"].attrs["ids"]]
            kind_names = [text(n) for n in f["events/kind"].attrs["names"]]
            event_time_s = f["events/time_s"][:]
            event_tool = f["events/tool"][:]
            event_kind = f["events/kind"][:]
            tools = []
            for index, tool_id in enumerate(ids):
                g = f["tools"][tool_id]
                force = g["force"][:]
                rows = {name: len(g[name]) for name in ("time_s", "force", "contact_count",
                                                        "compute_ns")}
                if len(set(rows.values())) != 1 or force.ndim != 2 or force.shape[1] != 3:
                    raise ValueError(f"tool {tool_id}: tick datasets of different lengths or "
                                     f"shapes ({rows}, force {force.shape})")
                latency_us = g["compute_ns"][:].astype(np.float64) * US_PER_NS
                events = [(float(t), kind_names[k] if 0 <= k < len(kind_names) else f"kind {k}")
                          for t, tool, k in zip(event_time_s, event_tool, event_kind)
                          if tool == index]
                rendered_time_s, rendered_magnitude_n = np.zeros(0), np.zeros(0)
                if "rendered" in g and len(g["rendered/time_ns"]) and len(g["time_s"]):
                    offset_s = float(np.median(g["time_s"][:] -
                                               g["send_time_ns"][:].astype(np.float64) * 1e-9))
                    rendered_time_s = g["rendered/time_ns"][:].astype(np.float64) * 1e-9 + offset_s
                    rendered_magnitude_n = np.linalg.norm(g["rendered/force"][:], axis=1)
                tools.append(ToolSeries(
                    rendered_time_s=rendered_time_s,
                    rendered_magnitude_n=rendered_magnitude_n,
                    id=tool_id,
                    time_s=g["time_s"][:],
                    force_n=force,
                    force_magnitude_n=np.linalg.norm(force, axis=1),
                    contact_count=g["contact_count"][:],
                    latency_us=latency_us,
                    latency_p50_us=nearest_rank(latency_us, 0.50),
                    latency_p99_us=nearest_rank(latency_us, 0.99),
                    latency_max_us=float(latency_us.max()) if len(latency_us) else 0.0,
                    events=events))
        except (KeyError, ValueError, IndexError, OSError) as e:
            raise Refused(f"{path}: damaged or incomplete palpate session recording ({e})")
        if not tools or all(len(t.time_s) == 0 for t in tools):
            raise Refused(f"{path}: an empty session (no tick recorded for any tool); "
                          "nothing to plot")
        return SessionSeries(file=path, model_id=text(f.attrs.get("model_id", "")),
                             complete="closed_utc" in f.attrs, tools=tools)


def title(session, what):
    name = os.path.basename(session.file)
    status = "" if session.complete else ", INCOMPLETE (never closed: plotted up to its last flush)"
    return f"{what}\n{name}, model {session.model_id}{status}"


def tool_rows(session, what):
    """A figure with one row of axes per tool, sharing the time axis."""
    n = len(session.tools)
    fig = new_figure(WIDTH_IN, TITLE_HEIGHT_IN + ROW_HEIGHT_IN * n)
    axes = fig.subplots(n, 1, sharex=True, squeeze=False)[:, 0]
    fig.suptitle(title(session, what))
    axes[-1].set_xlabel("time since session start (s)")
    return fig, axes


def mark_events(ax, tool):
    seen = set()
    for time_s, kind in tool.events:
        color, style = EVENT_STYLE.get(kind, UNKNOWN_EVENT_STYLE)
        ax.axvline(time_s, color=color, linestyle=style, linewidth=1.0, alpha=0.8,
                   label=None if kind in seen else f"event: {kind}")
        seen.add(kind)


def no_ticks(ax, tool):
    ax.set_title(f"tool {tool.id}")
    ax.text(0.5, 0.5, "no tick recorded", transform=ax.transAxes, ha="center", va="center")


def legend(ax):
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")


def force_figure(session):
    # A tick's force holds until the tool's next tick (docs/session-recording.md):
    # steps, not lines between ticks.
    fig, axes = tool_rows(session, "Force sent to the device, per tool")
    for ax, tool in zip(axes, session.tools):
        if len(tool.time_s) == 0:
            no_ticks(ax, tool)
            continue
        # |f| wide and pale underneath, so that a component equal to it shows.
        ax.plot(tool.time_s, tool.force_magnitude_n, drawstyle="steps-post", color="0.6",
                linewidth=3.5, label="|f|")
        for j, (axis, color) in enumerate(FORCE_COMPONENTS):
            ax.plot(tool.time_s, tool.force_n[:, j], drawstyle="steps-post", color=color,
                    linewidth=1.0, label=f"f{axis}")
        if len(tool.rendered_time_s):
            ax.plot(tool.rendered_time_s, tool.rendered_magnitude_n, drawstyle="steps-post",
                    color="tab:orange", linewidth=0.6, label="|f| rendered by the device")
        mark_events(ax, tool)
        ax.set_title(f"tool {tool.id}: max |f| {tool.force_magnitude_n.max():.3g} N")
        ax.set_ylabel("force (N)")
        ax.grid(True, alpha=0.3)
        legend(ax)
    return fig


def contacts_figure(session):
    # The recording keeps the contact forces per vertex: a point on a
    # triangle loads up to three, so these exceed the tool's contact points
    # (palpate-pliers' "max contacts"), and are named for what they count.
    fig, axes = tool_rows(session, "Vertices carrying contact force per tick, per tool")
    for ax, tool in zip(axes, session.tools):
        if len(tool.time_s) == 0:
            no_ticks(ax, tool)
            continue
        ax.plot(tool.time_s, tool.contact_count, drawstyle="steps-post", color="black",
                linewidth=1.0, label="loaded vertices")
        mark_events(ax, tool)
        ax.set_title(f"tool {tool.id}: at most {int(tool.contact_count.max())} loaded vertices "
                     "per tick")
        ax.set_ylabel("loaded vertices (count)")
        ax.yaxis.get_major_locator().set_params(integer=True)
        ax.set_ylim(bottom=0)
        ax.grid(True, alpha=0.3)
        legend(ax)
    return fig


def latency_cdf(latency_us):
    """The empirical cumulative distribution of one tool's latencies:
    (x, y) with x [n] µs the latencies sorted ascending and y [n] = (i + 1) / n
    the fraction of ticks at or below x[i]; drawn as steps ("steps-post")."""
    x = np.sort(np.asarray(latency_us, dtype=np.float64))
    y = np.arange(1, len(x) + 1, dtype=np.float64) / max(len(x), 1)
    return x, y


def label_log_axis(axis):
    """Plain numbers at 1, 2 and 5 of every decade: a session's latencies
    often span less than one decade, where powers of ten alone label nothing."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter
    axis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
    axis.set_major_formatter(FuncFormatter(lambda value, _: f"{value:g}"))
    axis.set_minor_formatter(NullFormatter())


def fraction_at_or_below(sorted_values, value):
    """The CDF at value: the share of sorted_values that are <= value."""
    return float(np.searchsorted(sorted_values, value, side="right")) / len(sorted_values)


def latency_axis_limits(session):
    """(left, right) µs of the log latency axis: a little beyond the fastest
    and slowest tick of the session. Ticks of 0 µs (below the clock's
    resolution) cannot sit on a log axis; they are clipped to its left edge,
    which is then at most 0.1 µs."""
    values = np.concatenate([t.latency_us for t in session.tools])
    positive = values[values > 0]
    lo = float(positive.min()) if len(positive) else 0.1
    if len(positive) < len(values):
        lo = min(lo, 0.1)
    hi = max(float(values.max()), lo)
    return lo / LATENCY_MARGIN, hi * LATENCY_MARGIN


def latency_figure(session):
    # A CDF on a log axis: the bulk (tens of µs) and a tail of slow ticks
    # (ms) both get room; on a linear axis the bulk is one sliver at the left.
    fig = new_figure(WIDTH_IN, LATENCY_HEIGHT_IN)
    ax = fig.subplots()
    fig.suptitle(title(session, "Daemon compute latency per tick (pose taken → feedback written), "
                                "cumulative distribution"))
    for i, tool in enumerate(session.tools):
        if len(tool.latency_us) == 0:
            continue
        color = TOOL_COLORS[i % len(TOOL_COLORS)]
        x, y = latency_cdf(tool.latency_us)
        ax.plot(x, y, drawstyle="steps-post", linewidth=1.5, color=color,
                label=f"tool {tool.id} ({len(tool.latency_us)} ticks)")
        for name, value, marker in (("p50", tool.latency_p50_us, "o"),
                                    ("p99", tool.latency_p99_us, "s"),
                                    ("max", tool.latency_max_us, "^")):
            ax.axvline(value, color=color, linestyle=":", linewidth=1.0, alpha=0.7)
            ax.plot([value], [fraction_at_or_below(x, value)], marker=marker, color=color,
                    linestyle="none", label=f"tool {tool.id} {name} {value:.1f} µs")
    ax.set_xscale("log", nonpositive="clip")
    ax.set_xlim(*latency_axis_limits(session))
    label_log_axis(ax.xaxis)
    ax.set_ylim(0.0, 1.02)
    ax.set_xlabel("compute latency (µs, log scale)")
    ax.set_ylabel("fraction of ticks at or below")
    ax.grid(True, which="both", alpha=0.3)
    legend(ax)
    return fig


def figures(session):
    """The plots, by file suffix: force, latency, contacts."""
    return {"force": force_figure(session), "latency": latency_figure(session),
            "contacts": contacts_figure(session)}


def output_stem(path):
    name = os.path.basename(path)
    suffix = ""
    if name.endswith(".partial"):
        name, suffix = name[:-len(".partial")], "-partial"
    stem, ext = os.path.splitext(name)
    return (stem if ext else name) + suffix


def write_pngs(figs, out_dir, stem):
    """Writes figs (suffix -> Figure) as out_dir/<stem>-<suffix>.png. Every
    PNG is rendered under a hidden temporary name in out_dir first, and only
    once all are rendered renamed into place: an error leaves none of them."""
    umask = os.umask(0)
    os.umask(umask)
    temps, paths = [], []
    try:
        for suffix, fig in figs.items():
            path = os.path.join(out_dir, f"{stem}-{suffix}.png")
            fd, tmp = tempfile.mkstemp(dir=out_dir, prefix=f".{stem}-{suffix}.png.tmp-")
            temps.append(tmp)
            with os.fdopen(fd, "wb") as out:
                fig.savefig(out, format="png")
                out.flush()
                os.fsync(out.fileno())
            os.chmod(tmp, 0o666 & ~umask)  # mkstemp's 0600 is not what a PNG wants
            paths.append(path)
        for tmp, path in zip(temps, paths):
            os.replace(tmp, path)
    finally:
        for tmp in temps:
            if os.path.exists(tmp):
                os.unlink(tmp)
    return paths


def main():
    parser = argparse.ArgumentParser(
        prog=PROGRAM, description="PNG plots of a palpate session recording: force and "
        "contacts against time per tool, compute latency distribution "
        "(docs/session-recording.md, \"Plots\").")
    parser.add_argument("file", help="a session file, or a <file>.partial left by a crash")
    parser.add_argument("--out", metavar="DIR",
                        help="directory for the PNGs, created if missing "
                        "(default: the session file's directory)")
    args = parser.parse_args()
    signal.signal(signal.SIGPIPE, signal.SIG_DFL)
    try:
        session = read_series(args.file)
    except Refused as e:
        print(f"{PROGRAM}: error: {' '.join(str(e).split())}", file=sys.stderr)
        return 2
    out_dir = args.out if args.out is not None else (os.path.dirname(args.file) or ".")
    try:
        os.makedirs(out_dir, exist_ok=True)
        paths = write_pngs(figures(session), out_dir, output_stem(args.file))
    except OSError as e:
        print(f"{PROGRAM}: error: cannot write the PNGs in {out_dir}: "
              f"{e.strerror or e}", file=sys.stderr)
        return 1
    for path in paths:
        print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
