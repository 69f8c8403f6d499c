#!/usr/bin/python3
"""Precompute benchmark: each method end to end on the reference livers, with
the machine's dgemm rate measured in the same run as the baseline.

Usage: bench/precompute_bench.py BUILD_DIR [--large]   (from the checkout)
Needs ../shared/data/liver (see docs/data.md); says so if absent.
Prints a Markdown table for BENCHMARKS.md and writes out/bench/*.json.
"""
import json
import os
import platform
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DATA = os.path.join(os.path.dirname(ROOT), "shared", "data", "liver")
# Posterior-superior box of the OpenHELP liver, as in config/openhelp-liver-*.toml (mm).
FIX = ["--fix-box", "-200", "100", "190", "100", "250", "250"]
MATERIAL = ["-E", "85e3", "--nu", "0.45"]


def dgemm_rate(build):
    p = subprocess.run([os.path.join(build, "bench", "palpate_dense_bench"), "--benchmark_format=json",
                        "--benchmark_repetitions=3", "--benchmark_report_aggregates_only=true"],
                       capture_output=True, text=True, check=True)
    data = json.loads(p.stdout)
    rates = {b["run_name"]: b["GFLOP/s"] / 1e9 if b["GFLOP/s"] > 1e6 else b["GFLOP/s"]
             for b in data["benchmarks"] if b.get("aggregate_name") == "median"}
    return rates, data["context"]


def precompute(build, name, mesh, method, extra=()):
    out_dir = os.path.join(ROOT, "out", "bench")
    os.makedirs(out_dir, exist_ok=True)
    out = os.path.join(out_dir, f"{name}-{method}.h5")
    cmd = [os.path.join(build, "precompute", "palpate-precompute"), "--mesh", mesh, "--mesh-unit", "mm",
           *MATERIAL, *FIX, "--method", method, "-o", out, "--json", "-q", *extra]
    t0 = time.monotonic()
    p = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.monotonic() - t0
    if p.returncode != 0:
        raise SystemExit(f"{name} {method}: exit {p.returncode}: {p.stderr}")
    report = json.loads(p.stdout)
    report["wall_seconds"] = wall
    with open(os.path.join(out_dir, f"{name}-{method}.json"), "w") as f:
        json.dump(report, f, indent=1)
    os.remove(out)
    return report


def main():
    build = sys.argv[1]
    large = "--large" in sys.argv
    if not os.path.isdir(DATA):
        raise SystemExit(f"precompute_bench: {DATA} is absent: the reference livers live in ../shared/data (see docs/data.md)")
    rates, context = dgemm_rate(build)
    dgemm = max(v for k, v in rates.items() if k.startswith("BM_dgemm"))
    print(f"machine: {platform.node()}, {os.cpu_count()} cores, {context.get('mhz_per_cpu')} MHz; BLAS {context.get('blas')}")
    print(f"dgemm (same run): {dgemm:.1f} GFLOP/s; dense rates: " +
          ", ".join(f"{k} {v:.1f}" for k, v in sorted(rates.items())))
    cases = [("h12", os.path.join(DATA, "openhelp-liver-h12.msh"), ()),
             ("h8", os.path.join(DATA, "openhelp-liver-h8.msh"), ())]
    if large:
        cases.append(("stl-100k", os.path.join(DATA, "openhelp-liver.stl"), ("--fill-size", "6.8")))
    print()
    print("| mesh | vertices / tets | N_S (compliance) | method | wall s | factor s | dense s | dense GFLOP/s | % of dgemm | peak RSS | G + factor | peak / (G + factor) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name, mesh, extra in cases:
        for method in ("condensation", "solves"):
            r = precompute(build, name, mesh, method, extra)
            m = r["methods"][method]
            g = r["memory"]["G_bytes"]
            peak = r["peak_rss_bytes"]
            print(f"| {name} | {r['mesh']['vertices']} / {r['mesh']['tetrahedra']} | {r['mesh']['compliance_vertices']} | {method} | "
                  f"{r['wall_seconds']:.2f} | {m['factor_seconds']:.2f} | {m['dense_seconds']:.2f} | {m['dense_gflop_per_s']:.1f} | "
                  f"{100 * m['dense_gflop_per_s'] / dgemm:.0f} % | {peak / 1e9:.2f} GB | {(g + m['bytes']) / 1e9:.2f} GB | {peak / (g + m['bytes']):.2f} |")
            sys.stdout.flush()


if __name__ == "__main__":
    main()
