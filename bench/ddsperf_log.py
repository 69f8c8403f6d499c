"""ddsperf ping's per-second latency lines, summarized for the round-trip
benchmarks (bench/dds_roundtrip.sh, bench/pliers_roundtrip.sh)."""

import re
import statistics

# "[pid] 3.000  host:pid size 1200 mean 24.5us min 8.4us 50% 25.1us 90% 36.1us 99% 43.8us max 517.5us cnt 908"
LINE = re.compile(r"\]\s+([\d.]+)\s+\S+ size (\d+) mean ([\d.]+)us min ([\d.]+)us 50% ([\d.]+)us "
                  r"90% ([\d.]+)us 99% ([\d.]+)us max ([\d.]+)us cnt (\d+)")


def summary(work, tag, mode, warmup, who):
    """Median over the seconds after @warmup of ddsperf's 50 % and 99 %, from
    WORK/ping-TAG.txt and WORK/ddsperf-TAG.cmd (see ddsperf_pair)."""
    path = f"{work}/ping-{tag}.txt"
    rows = [m.groups() for m in map(LINE.search, open(path)) if m]
    rows = [r for r in rows if float(r[0]) > warmup]
    if not rows:
        raise SystemExit(f"{who}: no latency lines from ddsperf ping ({tag}); its output:\n"
                         + open(path).read())
    return {"mode": mode, "size": int(rows[0][1]), "seconds": len(rows),
            "samples": sum(int(r[8]) for r in rows),
            "p50_us": statistics.median(float(r[4]) for r in rows),
            "p99_us": statistics.median(float(r[6]) for r in rows),
            "worst_second_p99_us": max(float(r[6]) for r in rows),
            "max_us": max(float(r[7]) for r in rows),
            "command": open(f"{work}/ddsperf-{tag}.cmd").read().strip()}
