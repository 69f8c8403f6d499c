#!/usr/bin/python3
"""bench/ddsperf_log.py on a fixed sample of ddsperf's output (no DDS runs).

ddsperf prints half its ping → pong → ping round trip (process_pong() in
Cyclone DDS's src/tools/ddsperf/ddsperf.c divides each sample by two); the
round-trip benchmarks compare palpate's full round trips with it, so the
summary must give twice the printed microseconds, under names that say
which is which. The sample is ddsperf 0.10.2's ping output (waitset mode,
1000 Hz, size 124), captured on the project VM on 2026-11-25.
Usage: ddsperf_log_test.py BENCH_DIR
"""
import os
import sys
import tempfile
import unittest

BENCH_DIR = None

SAMPLE = """\
[28351] participant vm:28351: new (self)
[28351] participant vm:28339: new
[28351] 1.000  vm:28339 size 124 mean 128.191us min 28.362us 50% 57.695us 90% 147.251us 99% 1654.497us max 2546.105us cnt 817
[28351] 1.000  rss:7.5MB vcsw:2578 ivcsw:292 ddsperf:5%+0% recvUC:2%+0% pong:2%+0%
[28351] 2.000  vm:28339 size 124 mean 45.671us min 29.708us 50% 45.742us 90% 51.711us 99% 63.720us max 134.405us cnt 1000
[28351] 2.000  rss:7.5MB vcsw:3841 ivcsw:2559 ddsperf:5%+0% recvUC:1%+0% pong:1%+0%
[28351] 3.000  vm:28339 size 124 mean 45.403us min 28.867us 50% 45.187us 90% 59.102us 99% 65.943us max 76.913us cnt 1000
[28351] 3.000  rss:7.5MB vcsw:3634 ivcsw:2266 ddsperf:4%+0% recvUC:2%+0%
[28351] ping timed out (total 135 times) ... sending new ping
[28351] 4.001  vm:28339 size 124 mean 49.582us min 25.197us 50% 44.571us 90% 62.557us 99% 115.597us max 2024.320us cnt 890
[28351] 4.001  rss:7.5MB vcsw:3318 ivcsw:1966 ddsperf:5%+0% recvUC:1%+0% pong:1%+0%
"""
COMMAND = "ddsperf -D 4 ping 1000Hz size 124 waitset  (with: ddsperf -D 7 pong waitset)"


class DdsperfLogTest(unittest.TestCase):
    def setUp(self):
        self.work = tempfile.TemporaryDirectory()
        self.write("ping-s.txt", SAMPLE)
        self.write("ddsperf-s.cmd", COMMAND + "\n")

    def tearDown(self):
        self.work.cleanup()

    def write(self, name, text):
        with open(os.path.join(self.work.name, name), "w") as f:
            f.write(text)

    # Comparisons are exact: the summary doubles a float parsed from the same
    # decimal text, and multiplying by two is exact in binary floating point.
    def test_round_trip_is_twice_what_ddsperf_prints(self):
        s = ddsperf_log.summary(self.work.name, "s", "waitset", 1.0, "test")
        # After the first second: the lines at 2.000, 3.000 and 4.001 s.
        self.assertEqual(s["seconds"], 3)
        self.assertEqual(s["samples"], 1000 + 1000 + 890)
        self.assertEqual(s["size"], 124)
        # Medians of the printed 50 % (45.742, 45.187, 44.571) and 99 %
        # (63.720, 65.943, 115.597), then doubled.
        self.assertEqual(s["printed_half_p50_us"], 45.187)
        self.assertEqual(s["printed_half_p99_us"], 65.943)
        self.assertEqual(s["ddsperf_rtt_p50_us"], 2 * 45.187)
        self.assertEqual(s["ddsperf_rtt_p99_us"], 2 * 65.943)
        self.assertEqual(s["ddsperf_rtt_worst_second_p99_us"], 2 * 115.597)
        self.assertEqual(s["ddsperf_rtt_max_us"], 2 * 2024.320)
        self.assertEqual(s["command"], COMMAND)

    def test_every_latency_says_whether_it_is_halved(self):
        s = ddsperf_log.summary(self.work.name, "s", "waitset", 1.0, "test")
        for key in s:
            if key.endswith("_us"):
                self.assertTrue(key.startswith(("ddsperf_rtt_", "printed_half_")), key)

    def test_rtt_us(self):
        self.assertEqual(ddsperf_log.rtt_us(37.7), 75.4)

    def test_no_latency_line_after_warmup_is_one_clear_error(self):
        with self.assertRaises(SystemExit) as raised:
            ddsperf_log.summary(self.work.name, "s", "waitset", 10.0, "dds_roundtrip")
        message = str(raised.exception)
        self.assertIn("dds_roundtrip: no latency lines from ddsperf ping (s) after its first 10 s", message)
        self.assertIn("want lines like", message)
        self.assertIn(os.path.join(self.work.name, "ping-s.txt"), message)


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: ddsperf_log_test.py BENCH_DIR")
    BENCH_DIR = sys.argv.pop(1)
    sys.path.insert(0, BENCH_DIR)
    import ddsperf_log
    unittest.main()
