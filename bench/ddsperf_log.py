"""ddsperf ping's per-second latency lines, turned into Cyclone DDS's true
round trip for the round-trip benchmarks (bench/dds_roundtrip.sh,
bench/pliers_roundtrip.sh).

ddsperf prints HALF its round trip. In its ping-pong mode, process_pong() in
src/tools/ddsperf/ddsperf.c (Cyclone DDS 0.10.2, the version Debian 12 ships;
unchanged in 0.10.5 and on master) takes, for every pong, the time now minus
the ping's source timestamp and divides it by two before handing it to
update_roundtrip(), whose statistics (mean, min, 50 %, 90 %, 99 %, max) are
what the "size … mean …us min …us 50% …us …" lines print: a one-way latency
estimate, not the ping → pong → ping time. palpate's round trips (request →
reply, pose → feedback) are full round trips, so every figure read here is
doubled before it is returned, and the returned names say "rtt"; the
printed, halved values keep a "printed_half" name. (Halving each sample and
doubling the percentile gives the percentile of the full round trips, up to
ddsperf's 1 ns integer rounding.)
"""

import re
import statistics

# "[pid] 3.000  host:pid size 1200 mean 24.5us min 8.4us 50% 25.1us 90% 36.1us 99% 43.8us max 517.5us cnt 908"
LINE = re.compile(r"\]\s+([\d.]+)\s+\S+ size (\d+) mean ([\d.]+)us min ([\d.]+)us 50% ([\d.]+)us "
                  r"90% ([\d.]+)us 99% ([\d.]+)us max ([\d.]+)us cnt (\d+)")

# ddsperf's printed latency is the round trip divided by this (see above).
PRINTED_FRACTION_OF_RTT = 0.5


def rtt_us(printed_half_us):
    """ddsperf's true ping → pong → ping round trip (µs) from a latency it
    printed (µs, half the round trip)."""
    return printed_half_us / PRINTED_FRACTION_OF_RTT


def summary(work, tag, mode, warmup, who):
    """Cyclone's round trip from WORK/ping-TAG.txt and WORK/ddsperf-TAG.cmd
    (see ddsperf_pair in roundtrip_common.sh): the median over the seconds
    after @warmup of ddsperf's 50 % and 99 %, their worst second and the
    largest max, all as full round trips in µs (ddsperf_rtt_*_us)."""
    path = f"{work}/ping-{tag}.txt"
    with open(path) as f:
        output = f.read()
    with open(f"{work}/ddsperf-{tag}.cmd") as f:
        command = f.read().strip()
    rows = [m.groups() for m in map(LINE.search, output.splitlines()) if m]
    rows = [r for r in rows if float(r[0]) > warmup]
    if not rows:
        raise SystemExit(f"{who}: no latency lines from ddsperf ping ({tag}) after its first {warmup:g} s; "
                         f"want lines like '[pid] 3.000  host:pid size 124 mean …us min …us 50% …us 90% …us "
                         f"99% …us max …us cnt …'; its output ({path}):\n" + output)
    printed_half_p50_us = statistics.median(float(r[4]) for r in rows)
    printed_half_p99_us = statistics.median(float(r[6]) for r in rows)
    return {"mode": mode, "size": int(rows[0][1]), "seconds": len(rows),
            "samples": sum(int(r[8]) for r in rows),
            "ddsperf_rtt_p50_us": rtt_us(printed_half_p50_us),
            "ddsperf_rtt_p99_us": rtt_us(printed_half_p99_us),
            "ddsperf_rtt_worst_second_p99_us": rtt_us(max(float(r[6]) for r in rows)),
            "ddsperf_rtt_max_us": rtt_us(max(float(r[7]) for r in rows)),
            "printed_half_p50_us": printed_half_p50_us,
            "printed_half_p99_us": printed_half_p99_us,
            "command": command}
