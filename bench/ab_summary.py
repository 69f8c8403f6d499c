#!/usr/bin/env python3
"""Medians (and ranges) of bench/ab_ticks.sh's runs, before against after."""
import glob
import json
import statistics
import sys

out = sys.argv[1]


def load(kind, version):
    runs = []
    for f in sorted(glob.glob(f"{out}/{kind}-{version}-*.json")):
        runs.append({b["name"]: b for b in json.load(open(f))["benchmarks"]})
    return runs


for kind, keys in [("solve", ["Hz", "GFLOP/s", "GB/s"]),
                   ("contact", ["p50_us", "p99_us", "p999_us", "GFLOP/s"])]:
    before, after = load(kind, "before"), load(kind, "after")
    print(f"{kind}: {len(before)} runs each")
    for name in before[0]:
        for key in keys:
            if key not in before[0][name]:
                continue
            b = [r[name][key] for r in before]
            a = [r[name][key] for r in after]
            mb, ma = statistics.median(b), statistics.median(a)
            print(f"  {name:42s} {key:8s} before {mb:11.4g} [{min(b):.4g} to {max(b):.4g}]"
                  f"  after {ma:11.4g} [{min(a):.4g} to {max(a):.4g}]  after/before {ma / mb:.3f}")
