#!/usr/bin/python3
"""Runs the shell blocks of the README and the tutorial as a user would.

A fenced block runs when the line before its ```sh (or ```bash) fence is

    <!-- doc-test -->                 run it
    <!-- doc-test: needs-data -->     run it when ../shared/data exists
                                      (the OpenHELP liver, docs/data.md)
    <!-- doc-test: timeout=600 -->    a longer limit than --timeout

(options separated by commas). GitHub does not show the comment.

A plain fenced block (``` with no language) after

    <!-- doc-test: quote -->

quotes what the document's last marked block before it printed, and cannot
go stale: its measured lines are compared with that block's output, in
order. They are palpate-pliers' per-tool `max |force| F N, max grip G N,
max contacts C` (F and G within 3 % + 0.05 N: a feedback that arrived a
tick late moves a maximum by a tick; C within one) and its grasp events'
`grasp (N points held)` (equal), and the rows of scripts/session_report.py's
table (the tool equal, its max force and max grip as above). A quote with none of them is an error (it
would check nothing); its other lines (latencies, counts that depend on
the machine's load) are the reader's example, not checked.

Blocks without a doc-test marker are not run, on purpose:
- the README's two commands, scripts/demo.sh and scripts/test.sh: they
  install packages and take minutes; CI runs them (.ci/run). This harness
  starts from the state the first one leaves: a build, and the sample organ
  in out/ (made here as demo.sh makes it, see `prelude`);
- commands that need root beyond this test's network namespace, write
  outside the checkout (/etc/palpate, /opt/palpate), install packages, build,
  or run for minutes (the demo, long fuzz runs);
- alternatives shown as options next to the command that runs, and
  placeholders the reader supplies (their own organ, a recording's name);
- a shell the reader opens (`sudo unshare --net -- ... bash`): this test
  already runs in a private network namespace, loopback only
  (palpate_isolated_test), which is where such a shell puts the reader.

Each document runs as one bash script (-e -o pipefail, inherit_errexit), its
marked blocks in document order sharing the shell's state (variables,
directory, background jobs), in a copy of the checkout: the tracked and
untracked-but-not-ignored files (`git ls-files`; a walk without build*/,
out/, node_modules/ and .git/ when there is no .git), with build/ and
viewer/node_modules as symlinks to the real ones and, when it exists, a
`shared` symlink beside the copy to the real ../shared, so that the
documents' relative paths (../shared/data/...) resolve. <build>/bin comes
first on PATH. A failure names the document, the block's line, the line of
the command and the command; a block over its time limit is stopped with
its whole process group. Anything still running when a document ends
(a daemon started with `&` and never stopped) is a failure too: the
documents stop what they start (`palpated ... & daemon=$!`, `kill $daemon`).

At least --min-blocks blocks must be found, and every one found must run
(but needs-data blocks without the data), so that losing the markers fails.

Usage: run_doc_blocks.py --build BUILD --source SOURCE [--doc FILE]...
                         [--min-blocks N] [--timeout S] [--keep]
"""
import argparse
import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import time

DEFAULT_DOCS = ["README.md", "docs/tutorial-stl-to-haptics.md"]
MARKER = re.compile(r"^<!--\s*doc-test\s*(?::\s*(?P<options>[^>]*?))?\s*-->\s*$")
# What a quote's measured lines say, and how close a run must come.
MAX_LINE = re.compile(r"max \|force\| (?P<force>\d+\.\d+) N, max grip (?P<grip>\d+\.\d+) N, "
                      r"max contacts (?P<contacts>\d+)")
HELD = re.compile(r"grasp \((?P<held>\d+) points? held\)")
# A row of scripts/session_report.py's table: tool, ticks, duration, in
# contact, grasping, max force N, mean force in contact N, max grip N, ...
REPORT_ROW = re.compile(r"^(?P<tool>\w+) +\d+ +[\d.]+ +[\d.]+ +[\d.]+ +(?P<force>[\d.]+) +[\d.]+ +"
                        r"(?P<grip>[\d.]+) +[\d.]+ +\d+")
QUOTE_RELATIVE, QUOTE_ABSOLUTE_N, QUOTE_CONTACTS = 0.03, 0.05, 1
FENCE_OPEN = re.compile(r"^(?P<fence>`{3,})\s*(?P<lang>\S*)")
SKIPPED_DIRS = {".git", "out", "node_modules"}


class Block:
    def __init__(self, doc, line, text, needs_data, timeout):
        self.doc, self.line, self.text = doc, line, text
        self.needs_data, self.timeout = needs_data, timeout
        self.quotes = []  # (line, text) of the quotes of its output that follow it


def measured(text):
    """The measured lines of a quote or an output: [(kind, values)] in order."""
    found = []
    for line in text.split("\n"):
        if m := MAX_LINE.search(line):
            found.append(("max", (float(m["force"]), float(m["grip"]), int(m["contacts"]))))
        if m := HELD.search(line):
            found.append(("held", int(m["held"])))
        if m := REPORT_ROW.match(line):
            found.append(("row", (float(m["force"]), float(m["grip"]), m["tool"])))
    return found


def check_quote(doc, line, quote, output):
    """The differences between a quote and the output it quotes, as messages."""
    want, got = measured(quote), measured(output)
    failures = []
    for kind in ("max", "held", "row"):
        w = [v for k, v in want if k == kind]
        g = [v for k, v in got if k == kind]
        if len(g) < len(w):
            failures.append(f"{doc}:{line}: the quote has {len(w)} '{kind}' line(s), the block printed {len(g)}")
        for i, (a, b) in enumerate(zip(w, g)):
            if kind == "held" and a != b:
                failures.append(f"{doc}:{line}: grasp {i + 1}: the quote says {a} point(s) held, the run {b}")
            if kind == "row" and a[2] != b[2]:
                failures.append(f"{doc}:{line}: report row {i + 1}: tool {b[2]}, the quote says {a[2]}")
            if kind in ("max", "row"):
                for what, x, y in (("max |force|", a[0], b[0]), ("max grip", a[1], b[1])):
                    if abs(x - y) > QUOTE_RELATIVE * x + QUOTE_ABSOLUTE_N:
                        failures.append(f"{doc}:{line}: summary {i + 1}: {what} {y:.3f} N, the quote says "
                                        f"{x:.3f} N (tolerance {QUOTE_RELATIVE:.0%} + {QUOTE_ABSOLUTE_N} N)")
                if kind == "max" and abs(a[2] - b[2]) > QUOTE_CONTACTS:
                    failures.append(f"{doc}:{line}: summary {i + 1}: max contacts {b[2]}, the quote says {a[2]}")
    return failures


def extract_blocks(doc, path, default_timeout):
    """The marked blocks of one Markdown file, in order. A marker not
    followed by a shell fence is an error: it would silently run nothing."""
    try:
        lines = open(path, encoding="utf-8").read().split("\n")
    except OSError as e:
        sys.exit(f"doc-test: {doc}: {e.strerror}")
    blocks, i = [], 0
    while i < len(lines):
        marker = MARKER.match(lines[i].strip())
        if not marker:
            i += 1
            continue
        needs_data, timeout = False, default_timeout
        options = [o.strip() for o in (marker["options"] or "").split(",") if o.strip()]
        if options == ["quote"]:
            fence = FENCE_OPEN.match(lines[i + 1]) if i + 1 < len(lines) else None
            if not fence or fence["lang"]:
                sys.exit(f"{doc}:{i + 1}: a doc-test quote marker must be followed by a plain ``` fence")
            if not blocks:
                sys.exit(f"{doc}:{i + 1}: a doc-test quote before any marked block: it quotes nothing")
            end = next((j for j in range(i + 2, len(lines)) if lines[j].startswith(fence["fence"])), None)
            if end is None:
                sys.exit(f"{doc}:{i + 2}: the block is never closed")
            quote = "\n".join(lines[i + 2:end])
            if not measured(quote):
                sys.exit(f"{doc}:{i + 2}: the quote has no measured line ('max |force| F N, max grip G N, "
                         "max contacts C', 'grasp (N points held)' or a session report's row): "
                         "it would check nothing")
            blocks[-1].quotes.append((i + 2, quote))
            i = end + 1
            continue
        for option in options:
            if option == "needs-data":
                needs_data = True
            elif option.startswith("timeout="):
                timeout = float(option.split("=", 1)[1])
            else:
                sys.exit(f"{doc}:{i + 1}: unknown doc-test option '{option}' "
                         "(accepted: needs-data, timeout=SECONDS; or quote alone)")
        fence = FENCE_OPEN.match(lines[i + 1]) if i + 1 < len(lines) else None
        if not fence or fence["lang"] not in ("sh", "bash", "shell"):
            sys.exit(f"{doc}:{i + 1}: a doc-test marker must be followed by a ```sh fence")
        body, j = [], i + 2
        while j < len(lines) and not lines[j].startswith(fence["fence"]):
            body.append(lines[j])
            j += 1
        if j == len(lines):
            sys.exit(f"{doc}:{i + 2}: the block is never closed")
        blocks.append(Block(doc, i + 2, body, needs_data, timeout))
        i = j + 1
    return blocks


def tracked_files(source):
    if os.path.isdir(os.path.join(source, ".git")):
        out = subprocess.run(
            ["git", "-C", source, "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
            check=True, capture_output=True).stdout.decode()
        return sorted({f for f in out.split("\0") if f})
    files = []
    for root, dirs, names in os.walk(source):
        rel = os.path.relpath(root, source)
        dirs[:] = [d for d in dirs
                   if d not in SKIPPED_DIRS and not (rel == "." and d.startswith("build"))]
        files += [os.path.normpath(os.path.join(rel, n)) for n in names]
    return sorted(files)


def copy_checkout(source, build, copy):
    """The checkout's files in COPY; build/ and the viewer's node_modules as
    symlinks (read, never written, by the marked blocks)."""
    for rel in tracked_files(source):
        src = os.path.join(source, rel)
        if not os.path.lexists(src):  # deleted in the working tree
            continue
        dst = os.path.join(copy, rel)
        os.makedirs(os.path.dirname(dst), exist_ok=True)
        shutil.copy2(src, dst, follow_symlinks=False)
    os.symlink(os.path.realpath(build), os.path.join(copy, "build"))
    node_modules = os.path.join(source, "viewer", "node_modules")
    if os.path.isdir(node_modules):
        os.symlink(node_modules, os.path.join(copy, "viewer", "node_modules"))


def interfaces_other_than_loopback():
    """The network interfaces this process sees, but lo (`ip`, not
    /sys/class/net, which shows the host's inside a namespace)."""
    ip = shutil.which("ip") or next((p for p in ("/usr/sbin/ip", "/sbin/ip") if os.path.exists(p)), "ip")
    out = subprocess.run([ip, "-o", "link", "show"], check=True, capture_output=True, text=True).stdout
    names = [line.split(":")[1].strip().split("@")[0] for line in out.splitlines() if ":" in line]
    return [name for name in names if name != "lo"]


def prelude(copy, env):
    """What the README's first command, scripts/demo.sh, leaves that the
    documents use: the sample organ's mesh and compliance file in out/."""
    print("doc-test: prelude: the sample organ in out/, as scripts/demo.sh makes it")
    os.makedirs(os.path.join(copy, "out"), exist_ok=True)
    for args in (["make-sample", "-o", "out/sample-organ.msh", "--size", "0.008"],
                 ["--job", "config/sample-organ.toml", "-q"]):
        if subprocess.run(["palpate-precompute", *args], cwd=copy, env=env,
                          stdin=subprocess.DEVNULL).returncode != 0:
            sys.exit(f"doc-test: prelude: palpate-precompute {' '.join(args)} failed")


def script_for(blocks, status_path):
    """One bash script for one document, and for each of its lines the
    (line in the document, its text) it came from."""
    lines, origin = [], []

    def emit(text, where=None):
        lines.append(text)
        origin.append(where)

    emit("set -eE -o pipefail")
    emit("shopt -s inherit_errexit")
    emit(f"exec 3>>{shlex.quote(status_path)}")
    emit(r"""trap 'printf "fail %s %s %s\n" "$?" "$LINENO" "${BASH_COMMAND//$'"'\n'"'/ }" >&3' ERR""")
    for index, block in enumerate(blocks):
        emit(f"printf 'begin {index}\\n' >&3")
        emit(f"printf '\\n==> %s:%s\\n' {shlex.quote(block.doc)} {block.line}")
        emit("cat <<'__DOC_TEST_BLOCK__'")
        for text in block.text:
            emit("$ " + text if text else "$")
        emit("__DOC_TEST_BLOCK__")
        for offset, text in enumerate(block.text):
            emit(text, (block.line + 1 + offset, text.strip()))
        emit(f"printf 'end {index}\\n' >&3")
    return "\n".join(lines) + "\n", origin


def alive_in_group(pgid):
    try:
        os.killpg(pgid, 0)
        return True
    except ProcessLookupError:
        return False


def stop_group(pgid):
    """SIGTERM the process group, SIGKILL what is left after 5 s."""
    for sig, grace in ((signal.SIGTERM, 5.0), (signal.SIGKILL, 2.0)):
        try:
            os.killpg(pgid, sig)
        except ProcessLookupError:
            return
        deadline = time.monotonic() + grace
        while time.monotonic() < deadline and alive_in_group(pgid):
            time.sleep(0.05)


def describe_group(pgid):
    """The command lines still running in a process group (for the report)."""
    found = []
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            if os.getpgid(int(pid)) != pgid:
                continue
            with open(f"/proc/{pid}/cmdline", "rb") as f:
                found.append(f"{pid} " + f.read().replace(b"\0", b" ").decode().strip())
        except (OSError, ProcessLookupError):
            continue
    return found


def run_document(doc, blocks, copy, env):
    """Runs the blocks of one document; returns a list of failure messages."""
    base = os.path.join(os.path.dirname(copy), re.sub(r"\W", "_", doc))
    status_path = base + ".status"
    script, origin = script_for(blocks, status_path)
    with open(base + ".sh", "w", encoding="utf-8") as f:
        f.write(script)
    # A file, not a pipe, for the status lines: a daemon the script starts
    # inherits the descriptor, and must not keep its reader waiting.
    open(status_path, "w").close()
    # The output goes to a file too, read back as it comes (shown in order)
    # and, at the end, split at each block's header for its quotes.
    output_path = base + ".out"
    with open(output_path, "wb") as output_file:
        process = subprocess.Popen(["bash", base + ".sh"], cwd=copy, env=env, stdin=subprocess.DEVNULL,
                                   stdout=output_file, stderr=subprocess.STDOUT, start_new_session=True)
    current, started, ended, fails, failures = None, None, set(), [], []
    pending, position, shown = "", 0, 0

    def show():
        nonlocal shown
        with open(output_path, "rb") as f:
            f.seek(shown)
            chunk = f.read()
        shown += len(chunk)
        sys.stdout.write(chunk.decode(errors="replace"))

    while True:
        code = process.poll()
        show()
        with open(status_path, encoding="utf-8") as f:
            f.seek(position)
            chunk = f.read()
            position = f.tell()
        pending += chunk
        *complete, pending = pending.split("\n")
        for message in complete:
            kind, _, rest = message.partition(" ")
            if kind == "begin":
                current, started = int(rest), time.monotonic()
            elif kind == "end":
                ended.add(int(rest))
                current = None
            elif kind == "fail":
                fail_code, line, command = rest.split(" ", 2)
                fails.append((fail_code, int(line), command))
        if code is not None:
            break
        if current is not None and time.monotonic() - started > blocks[current].timeout:
            block = blocks[current]
            running = "; ".join(describe_group(process.pid)) or "nothing"
            failures.append(f"{doc}:{block.line}: the block ran over its {block.timeout:.0f} s "
                            f"limit; still running: {running}")
            stop_group(process.pid)
            process.wait()
            return failures
        time.sleep(0.1)
    # Still running (after a moment to finish stopping): what the document
    # started and did not stop.
    deadline = time.monotonic() + 3
    while alive_in_group(process.pid) and time.monotonic() < deadline:
        time.sleep(0.05)
    show()
    if alive_in_group(process.pid):
        failures.append(f"{doc}: still running when the document ended (start them with "
                        f"`& pid=$!` and stop them with `kill $pid`): "
                        f"{'; '.join(describe_group(process.pid))}")
        stop_group(process.pid)
    if code != 0:
        block = blocks[current] if current is not None else None
        where = f"{doc}:{block.line}" if block else doc
        # The outermost failing command: the last ERR trap before the exit.
        detail = f"bash exit {code}"
        for fail_code, line, command in fails[-1:]:
            source = origin[line - 1] if 0 < line <= len(origin) else None
            if source:
                detail = f"line {source[0]}: `{source[1]}` (exit {fail_code})"
            else:
                detail = f"exit {fail_code} from `{command}`"
        failures.append(f"{where}: the block failed, {detail}")
    elif len(ended) != len(blocks):
        failures.append(f"{doc}: the script ended after {len(ended)} of {len(blocks)} blocks "
                        "(an `exit` in a block?)")
    else:
        output = open(output_path, encoding="utf-8", errors="replace").read()
        for index, block in enumerate(blocks):
            header = f"\n==> {block.doc}:{block.line}\n"
            begin = output.find(header)
            end = output.find("\n==> ", begin + len(header)) if begin >= 0 else -1
            printed = output[begin + len(header):end if end >= 0 else len(output)]
            for line, quote in block.quotes:
                checked = check_quote(doc, line, quote, printed)
                failures += checked
                if not checked:
                    print(f"doc-test: {doc}:{line}: the quote of the block at line {block.line} holds "
                          f"({len(measured(quote))} measured line(s))")
    return failures


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--build", required=True, help="the build directory (its bin/ goes on PATH)")
    parser.add_argument("--source", required=True, help="the checkout")
    parser.add_argument("--doc", action="append", help="a Markdown file, relative to the checkout "
                        f"(repeatable; default: {' '.join(DEFAULT_DOCS)})")
    parser.add_argument("--min-blocks", type=int, default=1,
                        help="fail if fewer marked blocks are found in all")
    parser.add_argument("--timeout", type=float, default=300, help="seconds per block (default 300)")
    parser.add_argument("--keep", action="store_true", help="keep the copy (its path is printed)")
    args = parser.parse_args()
    sys.stdout.reconfigure(line_buffering=True)  # in order with the blocks' own output
    source, build = os.path.realpath(args.source), os.path.realpath(args.build)
    docs = args.doc or DEFAULT_DOCS
    bin_dir = os.path.join(build, "bin")
    if not os.path.isdir(bin_dir):
        sys.exit(f"doc-test: {bin_dir} does not exist (build the palpate_bin target)")

    # The blocks start palpated and its clients: never where DDS could reach a
    # real interface.
    others = interfaces_other_than_loopback()
    if others:
        sys.exit(f"doc-test: this network namespace has {', '.join(others)} besides lo; run in a "
                 "private one: unshare --net -- sh -c 'ip link set lo up && exec ...' "
                 "(CTest's doc_commands does)")

    per_doc = [(doc, extract_blocks(doc, os.path.join(source, doc), args.timeout)) for doc in docs]
    found = sum(len(b) for _, b in per_doc)
    for doc, blocks in per_doc:
        print(f"doc-test: {doc}: {len(blocks)} marked block(s) at lines "
              f"{', '.join(str(b.line) for b in blocks) or '-'}")
    if found < args.min_blocks:
        sys.exit(f"doc-test: {found} marked block(s) found, expected at least {args.min_blocks} "
                 "(a lost <!-- doc-test --> marker?)")

    start = time.monotonic()
    work = tempfile.mkdtemp(prefix="palpate-doc-test-")
    copy = os.path.join(work, "palpate")
    shared = os.path.join(os.path.dirname(source), "shared")
    have_data = os.path.isdir(os.path.join(shared, "data"))
    failures, ran, skipped = [], 0, 0
    try:
        copy_checkout(source, build, copy)
        if os.path.isdir(shared):
            os.symlink(shared, os.path.join(work, "shared"))
        env = dict(os.environ, PATH=bin_dir + os.pathsep + os.environ.get("PATH", ""))
        env.pop("CYCLONEDDS_URI", None)  # the documents' default: palpate's loopback configuration
        prelude(copy, env)
        for doc, blocks in per_doc:
            runnable = []
            for block in blocks:
                if block.needs_data and not have_data:
                    print(f"doc-test: {doc}:{block.line}: skipped (no ../shared/data)")
                    skipped += 1
                else:
                    runnable.append(block)
            if not runnable:
                continue
            doc_start = time.monotonic()
            doc_failures = run_document(doc, runnable, copy, env)
            print(f"\ndoc-test: {doc}: {'FAILED' if doc_failures else 'ok'}, "
                  f"{len(runnable)} block(s) in {time.monotonic() - doc_start:.1f} s")
            failures += doc_failures
            if not doc_failures:
                ran += len(runnable)
    finally:
        if args.keep:
            print(f"doc-test: the copy is kept in {copy}")
        else:
            shutil.rmtree(work, ignore_errors=True)

    print(f"\ndoc-test: {found} block(s) found, {ran} ran, {skipped} skipped, "
          f"{len(failures)} failure(s), {time.monotonic() - start:.1f} s")
    for failure in failures:
        print(f"doc-test: FAILED {failure}")
    if not failures and ran + skipped != found:
        print(f"doc-test: FAILED only {ran} of {found} blocks ran")
        return 1
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
