#!/usr/bin/python3
"""Old against new feel traces (docs/tools.md, "The feel under regression tests").

Usage: scripts/feel_trace_plots.py OLD_DIR NEW_DIR OUT_DIR

For each NEW_DIR/<gesture>.csv (written by palpate_play_gesture) and its
OLD_DIR/<gesture>.csv: OUT_DIR/<gesture>.png, a row per tool: the force's
magnitude and components over time, old and new, and their difference at
the ticks both kept; the horizon (where round-off alone changes the trace,
beyond which the test compares nothing) marked. Prints one line per gesture:
max |ΔF| (N), where, and the horizons. Debian's python3-matplotlib.
"""

import csv
import math
import os
import sys


def read_trace(path):
    """{tool: {tick: (time_s, fx, fy, fz, state)}}, {tool: horizon tick}, ticks."""
    tools, horizons, ticks = {}, {}, 0
    with open(path, newline="") as f:
        lines = f.read().splitlines()
    rows = []
    for line in lines:
        if line.startswith("#"):
            words = line[1:].split()
            if words[:1] == ["horizon"] and len(words) == 3:
                horizons[words[1]] = int(words[2])
            if words[:1] == ["ticks"]:
                ticks = int(words[1])
        elif line.strip():
            rows.append(line)
    for r in csv.DictReader(rows):
        tools.setdefault(r["tool"], {})[int(r["tick"])] = (
            float(r["time_s"]), float(r["fx_n"]), float(r["fy_n"]), float(r["fz_n"]), r["state"])
    return tools, horizons, ticks


def main():
    if len(sys.argv) != 4:
        print(__doc__.strip().splitlines()[2], file=sys.stderr)
        return 2
    old_dir, new_dir, out_dir = sys.argv[1:]
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    os.makedirs(out_dir, exist_ok=True)
    names = sorted(n[:-4] for n in os.listdir(new_dir) if n.endswith(".csv"))
    for name in names:
        new, new_h, new_ticks = read_trace(os.path.join(new_dir, name + ".csv"))
        old_path = os.path.join(old_dir, name + ".csv")
        old, old_h, _ = read_trace(old_path) if os.path.exists(old_path) else ({}, {}, 0)
        fig, axes = plt.subplots(len(new), 2, figsize=(13, 3.4 * len(new)), squeeze=False)
        worst = (0.0, 0.0, "")
        for row, tool in enumerate(sorted(new)):
            n = new[tool]
            o = old.get(tool, {})
            ax, dax = axes[row]
            for trace, label, style in ((o, "old", dict(color="0.6", lw=2.5)),
                                        (n, "new", dict(color="C3", lw=1))):
                if not trace:
                    continue
                ticks = sorted(trace)
                t = [trace[k][0] for k in ticks]
                ax.plot(t, [math.hypot(*trace[k][1:4]) for k in ticks], label=f"|F| {label}",
                        **style)
                for c, comp in enumerate("xyz"):
                    ax.plot(t, [trace[k][1 + c] for k in ticks], ls="--", lw=0.8,
                            color=style["color"] if label == "old" else f"C{c}",
                            label=f"F{comp} {label}")
            common = sorted(set(n) & set(o))
            if common:
                t = [n[k][0] for k in common]
                diff = [[n[k][1 + c] - o[k][1 + c] for c in range(3)] for k in common]
                mag = [math.hypot(*d) for d in diff]
                dax.plot(t, mag, color="k", lw=1.2, label="|ΔF|")
                for c, comp in enumerate("xyz"):
                    dax.plot(t, [d[c] for d in diff], lw=0.8, color=f"C{c}", label=f"ΔF{comp}")
                i = max(range(len(mag)), key=mag.__getitem__)
                if mag[i] >= worst[0]:
                    worst = (mag[i], t[i], tool)
            for a in (ax, dax):
                for h, style in ((old_h.get(tool), ":"), (new_h.get(tool), "-.")):
                    if h is not None and h < new_ticks:
                        a.axvline(h * 1e-3, color="0.3", ls=style, lw=0.8)
                a.set_xlabel("time (s)")
                a.grid(alpha=0.3)
            ax.set_ylabel(f"{tool}: force on the tool (N)")
            dax.set_ylabel("new − old (N)")
            ax.legend(fontsize=7, ncol=4, loc="upper right")
            dax.legend(fontsize=7, ncol=4, loc="upper right")
        fig.suptitle(f"{name}: old (grey) and new feel; dotted/dash-dot: old/new horizon")
        fig.tight_layout()
        png = os.path.join(out_dir, name + ".png")
        fig.savefig(png, dpi=90)
        plt.close(fig)
        horizons = ", ".join(f"{t} until {h * 1e-3:.3f} s" for t, h in sorted(new_h.items())
                             if h < new_ticks) or "whole trace compared"
        if not old:
            print(f"  {name:<20} new (no old trace); {horizons}; {png}")
        else:
            print(f"  {name:<20} max |ΔF| {worst[0]:.3g} N at {worst[1]:.3f} s ({worst[2] or '-'}); "
                  f"{horizons}; {png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
