#!/usr/bin/env python3
"""The plot of BENCHMARKS.md, "Rendering between answers": what a device
renders at 4 kHz between palpated's answers against the engine's answer at
every device pose (bench/render_accuracy.cpp).

Usage: plot_render_accuracy.py TRACE.csv RESULTS.json OUT.png [--title TEXT]

TRACE.csv is palpate_render_accuracy's --trace (one gesture at one round
trip: time, |F| of the reference, of the local model and of the held
answer); RESULTS.json its --json (RMS errors of every gesture and round
trip). Left: the force over time with an inset on a stretch of the glide;
right: the RMS errors, local model against held answer, per gesture and
round trip. Debian's python3-matplotlib.
"""
import argparse
import csv
import json

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("trace")
    parser.add_argument("results")
    parser.add_argument("out")
    parser.add_argument("--title", default="")
    args = parser.parse_args()

    t, ref, local, held = [], [], [], []
    with open(args.trace, newline="") as f:
        for row in csv.DictReader(f):
            t.append(float(row["time_s"]))
            ref.append(float(row["reference_n"]))
            local.append(float(row["local_n"]))
            held.append(float(row["held_n"]))
    with open(args.results) as f:
        results = json.load(f)["results"]

    fig, (ax, bars) = plt.subplots(1, 2, figsize=(13, 4.8), gridspec_kw={"width_ratios": [1.5, 1]})
    ax.plot(t, ref, color="black", lw=1.6, label="reference: the engine at every device pose")
    ax.plot(t, local, color="tab:blue", lw=0.9, label="local model, rendered at 4 kHz")
    ax.plot(t, held, color="tab:red", lw=0.9, ls="--", label="last answer held")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("|F| on the tool (N)")
    ax.set_title(args.title or "glide")
    ax.legend(loc="upper left", fontsize=8)
    # An inset on a stretch where the hand moves in contact.
    inset = ax.inset_axes([0.58, 0.08, 0.4, 0.4])
    lo, hi = 0.5, 0.56
    idx = [i for i, x in enumerate(t) if lo <= x <= hi]
    if idx:
        for ys, color, ls in ((ref, "black", "-"), (local, "tab:blue", "-"), (held, "tab:red", "--")):
            inset.plot([t[i] for i in idx], [ys[i] for i in idx], color=color, ls=ls, lw=1)
        inset.set_title(f"{lo}-{hi} s", fontsize=7)
        inset.tick_params(labelsize=6)

    labels, rms_local, rms_held = [], [], []
    for r in results:
        labels.append(f"{r['gesture']}\n{r['round_trip_ms']:g} ms")
        rms_local.append(r["rms_local_n"])
        rms_held.append(r["rms_held_n"])
    x = range(len(labels))
    bars.barh([i + 0.2 for i in x], rms_held, height=0.4, color="tab:red", label="held")
    bars.barh([i - 0.2 for i in x], rms_local, height=0.4, color="tab:blue", label="local model")
    bars.set_yticks(list(x))
    bars.set_yticklabels(labels, fontsize=7)
    bars.invert_yaxis()
    bars.set_xscale("log")
    bars.set_xlabel("RMS error against the reference (N)")
    bars.legend(fontsize=8)
    for i, (a, b) in enumerate(zip(rms_local, rms_held)):
        bars.text(max(a, b) * 1.1, i, f"{b / a:.2f}×", va="center", fontsize=7)
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)


if __name__ == "__main__":
    main()
