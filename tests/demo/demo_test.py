#!/usr/bin/python3
"""The README's first command, scripts/demo.sh, run twice as a returning
user runs it, against the already-built tree (docs/viewer.md, "The demo").

The demo installs what is missing (nothing here: install-deps.sh only
checks), configures and builds BUILD_DIR (PALPATE_BUILD_DIR; CMake registers
this test only for a Release Ninja tree, the demo's own configuration, so
both are no-ops on an up-to-date tree), precomputes, serves the organ with
palpated in its own private network namespace, takes headless Chromium's
screenshots, plays palpate-client's palpation and the pliers' gesture once
(PALPATE_DEMO_REPEAT=1) and prints its summary. Its outputs go to a folder
of this test (PALPATE_DEMO_OUT), never the developer's out/demo; the organ
is the sample organ (make-sample, as the demo makes it) with a copy of
config/sample-organ.toml whose mesh and compliance file are in that folder
too, passed as `scripts/demo.sh JOB.toml` (the demo's documented job
argument), so the developer's out/sample-organ.* are not touched either.

Asserted, for both runs: exit status 0; the closing line "done in T:
install I, build B, precompute P, the rest R; processes left running: 0 of
N started" (N >= 4: the namespace's holder, palpated, the viewer, the
screenshots), its four parts adding up to the total within 0.4 s (each is
printed rounded down to 0.1 s); headless Chromium's viewer.png; no process
of the demo left afterwards (its process group, and any process naming
this test's folder). The first run precomputes (no "kept"); the second
keeps the compliance file ("kept (--reuse): it already holds this
problem", the file's inode, size and mtime unchanged); the first run's
recordings and their plots still exist, unchanged, after the second, which
added one recording of its own, and the demo's listing counts them all.
No timing is asserted.

What the demo prints cannot go stale: README's "What the demo prints"
block quotes, per tool, the line "max |force| F N, max grip G N, max
contacts C" and the grasp events' "(N point(s) held)"; the first run must
print the same tools with F and G within 3 % + 0.05 N of the quoted ones
(a repeat of the gesture, or a feedback that arrived late, moves a maximum
by a tick), C within one and the same held counts. And the demo's default
tools stay within their 8 N device limit: no tool's max |force| reaches it
(the gestures are sized for it, config/gestures/demo.toml).

CTest runs it inside a private network namespace whose only interface is
loopback (palpate_isolated_test), as root: the demo creates its own nested
namespace. It refuses to run anywhere else.

Usage: demo_test.py BUILD_DIR SOURCE_DIR WORK_DIR
"""
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import time

RUN_TIMEOUT_S = 100  # one demo run; about 18 s on two cores
DONE = re.compile(
    r"^demo: done in (?P<total>\d+\.\d) s: install (?P<install>\d+\.\d) s, "
    r"build (?P<build>\d+\.\d) s, precompute (?P<precompute>\d+\.\d) s, "
    r"the rest (?P<rest>\d+\.\d) s; processes left running: (?P<left>\d+) of "
    r"(?P<started>\d+) started$", re.M)
KEPT = "kept (--reuse): it already holds this problem"
# Four parts, each rounded down to 0.1 s, against a total rounded down too.
PARTS_TOLERANCE_S = 0.4
# README's quoted summary against a run: forces and grips (N).
QUOTED_RELATIVE, QUOTED_ABSOLUTE_N = 0.03, 0.05
DEFAULT_FORCE_LIMIT_N = 8.0  # palpated's default tools (docs/tools.md, "The tool")
TOOL_LINE = re.compile(r"^  (?P<tool>\w+): \d+ poses", re.M)
MAX_LINE = re.compile(r"max \|force\| (?P<force>\d+\.\d+) N, max grip (?P<grip>\d+\.\d+) N, "
                      r"max contacts (?P<contacts>\d+)")
HELD = re.compile(r"^ +\d+\.\d+ s +(?P<tool>\w+) +grasp \((?P<held>\d+) points? held\)", re.M)


def fail(message):
    sys.exit(f"demo_test: {message}")


def interfaces_other_than_loopback():
    ip = shutil.which("ip") or "/usr/sbin/ip"
    out = subprocess.run([ip, "-o", "link", "show"], check=True, capture_output=True, text=True).stdout
    names = [line.split(":")[1].strip().split("@")[0] for line in out.splitlines() if ":" in line]
    return [name for name in names if name != "lo"]


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def processes_naming(text):
    """The processes whose command line contains TEXT (but this one)."""
    found = []
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as f:
                cmdline = f.read().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        if text in cmdline and int(pid) != os.getpid():
            found.append(f"{pid}: {cmdline.strip()}")
    return found


def run_demo(name, source, job, env, log_path):
    print(f"demo_test: {name}: scripts/demo.sh {job}", flush=True)
    started = time.monotonic()
    with open(log_path, "w") as log:
        process = subprocess.Popen(["scripts/demo.sh", job], cwd=source, env=env, stdin=subprocess.DEVNULL,
                                   stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
        try:
            status = process.wait(timeout=RUN_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGTERM)
            process.wait()
            fail(f"{name}: the demo ran over {RUN_TIMEOUT_S} s and was stopped; its output: {log_path}")
    output = open(log_path, encoding="utf-8", errors="replace").read()
    print(f"demo_test: {name}: exit {status} after {time.monotonic() - started:.1f} s (output: {log_path})")
    if status != 0:
        print(output[-4000:])
        fail(f"{name}: scripts/demo.sh exited {status}")
    # Nothing of the demo may outlive it: its process group (everything it
    # started with &), and whatever names this test's folder (palpated's
    # --record, the screenshots' --out).
    time.sleep(0.2)
    try:
        os.killpg(process.pid, signal.SIGKILL)  # raises when none is left
        fail(f"{name}: processes of the demo's process group {process.pid} were still running (now killed)")
    except ProcessLookupError:
        pass
    left = processes_naming(env["PALPATE_DEMO_OUT"])
    if left:
        fail(f"{name}: still running after the demo: {left}")
    return output


def check_run(name, output, out):
    lines = DONE.findall(output)
    match = DONE.search(output)
    if not match or len(lines) != 1:
        fail(f"{name}: want one closing line 'demo: done in T s: install I s, build B s, precompute P s, "
             f"the rest R s; processes left running: 0 of N started', found {len(lines)}")
    print(f"demo_test: {name}: {match.group(0)}")
    parts = sum(float(match[k]) for k in ("install", "build", "precompute", "rest"))
    if abs(parts - float(match["total"])) > PARTS_TOLERANCE_S:
        fail(f"{name}: install + build + precompute + the rest = {parts:.1f} s, "
             f"total {match['total']} s (tolerance {PARTS_TOLERANCE_S} s)")
    if "demo: no screenshots" in output or not os.path.isfile(os.path.join(out, "viewer.png")):
        fail(f"{name}: no screenshot {out}/viewer.png")
    if int(match["left"]) != 0 or int(match["started"]) < 4:
        fail(f"{name}: processes left running: {match['left']} of {match['started']} started "
             "(want 0 of at least 4: holder, palpated, viewer, screenshots)")


def summary(text):
    """{tool: (max force N, max grip N, max contacts)} and [(tool, held)] of a demo's output."""
    tools = {}
    for match in TOOL_LINE.finditer(text):
        # Its "max |force|" line is the second after "  TOOL: N poses".
        line = MAX_LINE.search("\n".join(text[match.end():].splitlines()[1:3]))
        if line:
            tools[match["tool"]] = (float(line["force"]), float(line["grip"]), int(line["contacts"]))
    return tools, [(m["tool"], int(m["held"])) for m in HELD.finditer(text)]


def readme_quote(source):
    """The first fenced block after README's heading "## What the demo prints"."""
    text = open(os.path.join(source, "README.md"), encoding="utf-8").read()
    heading = text.find("\n## What the demo prints")
    if heading < 0:
        fail('README.md has no heading "## What the demo prints"; update this test')
    start = text.find("\n```\n", heading)
    end = text.find("\n```\n", start + 1)
    if start < 0 or end < 0:
        fail('README.md: no fenced block after "## What the demo prints"')
    return text[start + 5:end]


def check_quoted_summary(name, output, source):
    quoted, quoted_held = summary(readme_quote(source))
    printed, printed_held = summary(output)
    if not quoted:
        fail("README.md's demo output quotes no 'max |force| F N, max grip G N, max contacts C' line; update this test")
    if set(quoted) != set(printed):
        fail(f"{name}: README quotes tools {sorted(quoted)}, the demo printed {sorted(printed)}")
    for tool, (force, grip, contacts) in quoted.items():
        run = printed[tool]
        for what, want, got in (("max |force|", force, run[0]), ("max grip", grip, run[1])):
            if abs(got - want) > QUOTED_RELATIVE * want + QUOTED_ABSOLUTE_N:
                fail(f"{name}: {tool}: {what} {got:.3f} N, README says {want:.3f} N (tolerance "
                     f"{QUOTED_RELATIVE:.0%} + {QUOTED_ABSOLUTE_N} N): regenerate README's block from a demo run")
        if abs(run[2] - contacts) > 1:
            fail(f"{name}: {tool}: max contacts {run[2]}, README says {contacts} (tolerance 1)")
        if run[0] >= DEFAULT_FORCE_LIMIT_N - 1e-3:
            fail(f"{name}: {tool}: max |force| {run[0]:.3f} N reaches the default tools' "
                 f"{DEFAULT_FORCE_LIMIT_N} N limit: the demo's gesture must stay within it")
    # A grasp's held points, in the order they come (the quote may elide later ones).
    for (tool, held), got in zip(quoted_held, printed_held):
        if (tool, held) != got:
            fail(f"{name}: grasp events: README quotes {tool} holding {held}, the demo printed "
                 f"{got[0]} holding {got[1]}")
    if len(printed_held) < len(quoted_held):
        fail(f"{name}: README quotes {len(quoted_held)} grasp events, the demo printed {len(printed_held)}")
    print(f"demo_test: {name}: the summary README quotes holds: {printed}")


def recordings(folder):
    """{recording: mtime_ns} in the demo's recordings folder."""
    path = os.path.join(folder, "recordings")
    return {n: os.stat(os.path.join(path, n)).st_mtime_ns for n in os.listdir(path) if n.endswith(".h5")}


def check_plots(name, out, sessions):
    for session in sessions:
        for kind in ("force", "latency", "contacts"):
            plot = os.path.join(out, f"{session[:-3]}-{kind}.png")
            if not os.path.isfile(plot):
                fail(f"{name}: {plot} is missing")


def main():
    if len(sys.argv) != 4:
        fail("usage: demo_test.py BUILD_DIR SOURCE_DIR WORK_DIR")
    build, source, work = (os.path.realpath(a) for a in sys.argv[1:])
    others = interfaces_other_than_loopback()
    if others:
        fail(f"refusing to start DDS outside a private network namespace (interfaces: lo {' '.join(others)}); "
             "run it through ctest (palpate_isolated_test)")
    if os.geteuid() != 0:
        fail("the demo creates a private network namespace: run the test as root")

    shutil.rmtree(work, ignore_errors=True)
    organ, out = os.path.join(work, "organ"), os.path.join(work, "demo")
    os.makedirs(organ)
    # The sample organ as the demo makes it, and its job with the mesh and
    # the compliance file beside it.
    subprocess.run([os.path.join(build, "bin", "palpate-precompute"), "make-sample", "-o",
                    os.path.join(organ, "sample-organ.msh"), "--size", "0.008"],
                   check=True, stdout=subprocess.DEVNULL)
    job_text = open(os.path.join(source, "config", "sample-organ.toml"), encoding="utf-8").read()
    for before, after in (('"../out/sample-organ.msh"', '"sample-organ.msh"'),
                          ('"../out/sample-organ.h5"', '"sample-organ.h5"')):
        if before not in job_text:
            fail(f"config/sample-organ.toml no longer names {before}; update this test")
        job_text = job_text.replace(before, after)
    job = os.path.join(organ, "sample-organ.toml")
    with open(job, "w", encoding="utf-8") as f:
        f.write(job_text)
    compliance = os.path.join(organ, "sample-organ.h5")

    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    env.update(PALPATE_BUILD_DIR=build, PALPATE_DEMO_OUT=out, PALPATE_DEMO_REPEAT="1",
               PALPATE_DEMO_PORT=str(free_port()), PALPATE_DEMO_NETNS="private")

    # ---- the first run: precomputes, records one session
    first = run_demo("first run", source, job, env, os.path.join(work, "first.log"))
    check_run("first run", first, out)
    check_quoted_summary("first run", first, source)
    if KEPT in first:
        fail("first run: the compliance file did not exist, yet the precompute says it kept it")
    if not os.path.isfile(compliance):
        fail(f"first run: no compliance file {compliance}")
    before = os.stat(compliance)
    first_recordings = recordings(out)
    if not first_recordings:
        fail(f"first run: no recording in {out}/recordings")
    check_plots("first run", out, first_recordings)

    # ---- the second run: reuses the compliance file, keeps the recordings
    env["PALPATE_DEMO_PORT"] = str(free_port())
    second = run_demo("second run", source, job, env, os.path.join(work, "second.log"))
    check_run("second run", second, out)
    if KEPT not in second:
        fail(f"second run: the precompute did not say '{KEPT}'")
    after = os.stat(compliance)
    if (after.st_ino, after.st_mtime_ns, after.st_size) != (before.st_ino, before.st_mtime_ns, before.st_size):
        fail(f"second run: {compliance} was rewritten (inode, mtime or size changed) although it was kept")
    second_recordings = recordings(out)
    for name, mtime in first_recordings.items():
        if name not in second_recordings:
            fail(f"second run: the first run's recording {name} is gone")
        if second_recordings[name] != mtime:
            fail(f"second run: the first run's recording {name} was modified")
    new = sorted(set(second_recordings) - set(first_recordings))
    if len(new) != 1:
        fail(f"second run: want one new recording, found {new}")
    check_plots("second run", out, second_recordings)
    listed = f"({len(second_recordings)} recorded session(s) in {out}/recordings, earlier runs' kept)"
    if listed not in second:
        fail(f"second run: the listing does not say '{listed}'")
    print(f"demo_test: ok: the compliance file kept, recordings {sorted(first_recordings)} kept, {new} added")


if __name__ == "__main__":
    main()
