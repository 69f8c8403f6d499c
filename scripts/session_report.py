#!/usr/bin/python3
"""The per-tool assessment of a palpate session recording.

Reads a file written by palpated's session recorder (docs/session-recording.md)
and prints, per tool: duration, time in contact, time grasping, maximum force,
mean force in contact, maximum grip, path length, number of grasps, ticks and
dropped ticks. The values are computed here from the datasets, with the
definitions of the document, so a "<file>.partial" left by a crash (which has
no summary attributes) is assessed too, up to its last flush.

Usage: session_report.py FILE [--json]
Exit codes: 0, or 2 for a missing, unreadable or foreign file (one line on
stderr).
"""
import argparse
import json
import os
import signal
import sys

import h5py
import numpy as np

PROGRAM = "session_report"
FORMAT = "palpate-session"
FORMAT_VERSION = 1


class Refused(Exception):
    """A file this script does not assess; the message says why."""


def text(value):
    """An attribute as str (h5py gives bytes for fixed-length strings)."""
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace")
    return str(value)


def open_session(path):
    if not os.path.exists(path):
        raise Refused(f"{path}: no such file")
    if not os.path.isfile(path):
        raise Refused(f"{path}: not a file")
    if not os.access(path, os.R_OK):
        raise Refused(f"{path}: not readable by this user")
    if not h5py.is_hdf5(path):
        raise Refused(f"{path}: not an HDF5 file; expected a palpate session recording "
                      "(docs/session-recording.md)")
    try:
        f = h5py.File(path, "r")
    except OSError as e:
        if "lock" in str(e):
            raise Refused(f"{path}: open for writing by another process (palpated still "
                          "recording?); wait for the session to close, or set "
                          "HDF5_USE_FILE_LOCKING=FALSE to read it as of its last flush")
        raise Refused(f"{path}: HDF5 cannot open it (truncated or corrupt?): {e}")
    fmt = f.attrs.get("format")
    if fmt is None:
        f.close()
        raise Refused(f"{path}: an HDF5 file without a 'format' attribute, not a palpate "
                      f"session recording (format '{FORMAT}')")
    if text(fmt) != FORMAT:
        f.close()
        raise Refused(f"{path}: a '{text(fmt)}' file, not a palpate session recording "
                      f"(format '{FORMAT}')")
    version = f.attrs.get("format_version")
    if version is None:
        f.close()
        raise Refused(f"{path}: no format_version attribute; a palpate session recording has "
                      "one")
    if int(version) != FORMAT_VERSION:
        f.close()
        raise Refused(f"{path}: format_version {int(version)}; this script reads version "
                      f"{FORMAT_VERSION}")
    return f


def assess_tool(group):
    """The assessment of one /tools/<id> group, from its datasets.

    A tick's state and force hold until the tool's next tick: the interval
    t[k] - t[k-1] counts as in contact when tick k-1 is not free, as grasping
    when tick k-1 is grasping (a non-increasing time adds nothing).
    """
    names = [text(n) for n in group["state"].attrs["names"]]
    free, grasping = names.index("free"), names.index("grasping")
    t = group["time_s"][:]
    state = group["state"][:].astype(np.int64)
    force = np.linalg.norm(group["force"][:], axis=1)
    position = group["position"][:]
    grip = group["grip"][:]
    n = len(t)
    dt = np.maximum(np.diff(t), 0.0)
    opened_by_contact = state[:-1] != free
    opened_by_grasp = state[:-1] == grasping
    time_in_contact = float(dt[opened_by_contact].sum())
    force_time = float((force[:-1][opened_by_contact] * dt[opened_by_contact]).sum())
    is_grasping = state == grasping
    dropped = group.attrs.get("dropped_ticks")
    return {
        "id": group.name.rsplit("/", 1)[-1],
        "index": int(group.attrs["index"]),
        "ticks": n,
        "duration_s": float(t[-1] - t[0]) if n else 0.0,
        "time_in_contact_s": time_in_contact,
        "time_grasping_s": float(dt[opened_by_grasp].sum()),
        "max_force_n": float(force.max()) if n else 0.0,
        "mean_force_in_contact_n": force_time / time_in_contact if time_in_contact > 0 else 0.0,
        "max_grip_n": float(max(grip.max(), 0.0)) if n else 0.0,
        "path_length_m": float(np.linalg.norm(np.diff(position, axis=0), axis=1).sum()),
        "grasps": int(is_grasping[:1].sum() + (is_grasping[1:] & ~is_grasping[:-1]).sum()),
        "dropped_ticks": None if dropped is None else int(dropped),
    }


def assess(path):
    with open_session(path) as f:
        try:
            ids = [text(i) for i in f["tools"].attrs["ids"]]
            tools = [assess_tool(f["tools"][i]) for i in ids]
        except (KeyError, ValueError) as e:
            raise Refused(f"{path}: damaged or incomplete palpate session recording ({e})")
        a = f.attrs
        closed = a.get("closed_utc")
        return {
            "file": path,
            "format_version": int(a["format_version"]),
            "model_id": text(a.get("model_id", "")),
            "model_file": text(a.get("model_file", "")),
            "daemon_id": text(a.get("daemon_id", "")),
            "started_utc": text(a.get("started_utc", "")),
            "closed_utc": None if closed is None else text(closed),
            "complete": closed is not None,
            "dropped_events": None if "dropped_events" not in a else int(a["dropped_events"]),
            "tools": tools,
        }


COLUMNS = [  # key, header, format
    ("id", "tool", "{}"),
    ("ticks", "ticks", "{}"),
    ("duration_s", "duration s", "{:.3f}"),
    ("time_in_contact_s", "in contact s", "{:.3f}"),
    ("time_grasping_s", "grasping s", "{:.3f}"),
    ("max_force_n", "max force N", "{:.3f}"),
    ("mean_force_in_contact_n", "mean force in contact N", "{:.3f}"),
    ("max_grip_n", "max grip N", "{:.3f}"),
    ("path_length_m", "path m", "{:.4f}"),
    ("grasps", "grasps", "{}"),
    ("dropped_ticks", "dropped", "{}"),
]


def table(report):
    status = (f"closed {report['closed_utc']}" if report["complete"] else
              "INCOMPLETE: never closed (a crash?); assessed up to its last flush, drops unknown")
    lines = [
        f"session {report['file']}",
        f"  model {report['model_id']} ({report['model_file']}), daemon {report['daemon_id']}",
        f"  started {report['started_utc']}, {status}",
        "",
    ]
    rows = [[h for _, h, _ in COLUMNS]]
    for tool in report["tools"]:
        rows.append(["?" if tool[k] is None else f.format(tool[k]) for k, _, f in COLUMNS])
    widths = [max(len(r[i]) for r in rows) for i in range(len(COLUMNS))]
    for r in rows:
        cells = [r[0].ljust(widths[0])] + [c.rjust(w) for c, w in zip(r[1:], widths[1:])]
        lines.append("  ".join(cells).rstrip())
    return "\n".join(lines)


def main():
    parser = argparse.ArgumentParser(
        prog=PROGRAM, description="Per-tool assessment of a palpate session recording "
        "(docs/session-recording.md).")
    parser.add_argument("file", help="a session file, or a <file>.partial left by a crash")
    parser.add_argument("--json", action="store_true", help="machine-readable output")
    args = parser.parse_args()
    signal.signal(signal.SIGPIPE, signal.SIG_DFL)  # quietly stop when piped into head
    try:
        report = assess(args.file)
    except Refused as e:
        print(f"{PROGRAM}: error: {' '.join(str(e).split())}", file=sys.stderr)
        return 2
    print(json.dumps(report, indent=2) if args.json else table(report))
    return 0


if __name__ == "__main__":
    sys.exit(main())
