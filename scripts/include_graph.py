#!/usr/bin/env python3
"""The include graph of palpate's C++ source units, and the layer rule.

A unit is a source file with its header (x.cpp and x.hpp are one unit).
Prints the number of units, of include edges between units, and of levels
(the longest chain of includes); then checks the layer rule of
docs/architecture.md: a unit of a layer includes only units of its own
layer or of the layers beneath it (core < file < offline, runtime <
transport < daemon, device; offline and runtime do not include each other,
nor do daemon and device), and the programs include only the library's
public headers. Inside the runtime, the same rule holds between its rooms
(lib/runtime/src/<room>/, lib/runtime/internal/palpate/runtime/<room>/):
a room includes only rooms of a lower rank (ROOMS below) and itself;
rooms of one rank do not include each other.

    scripts/include_graph.py [ROOT]          # the numbers, then the rule
    scripts/include_graph.py --check [ROOT]  # exit 1 if the rule is broken
    scripts/include_graph.py --programs-as-one [ROOT]
        # each program folder (precompute/, server/, clients/, viewer/,
        # bench/, fuzz/, examples/) counted as one unit

Reads the code as text: `#include "..."` lines, resolved against the
repository's include folders. Needs only Python 3.
"""
import os
import re
import sys
from collections import defaultdict

LAYERS = {"core": 0, "file": 1, "offline": 2, "runtime": 2, "transport": 3, "daemon": 4,
          "device": 4}
# Layers of one rank that must not include each other.
SIBLINGS = {("offline", "runtime"), ("runtime", "offline"), ("daemon", "device"),
            ("device", "daemon")}
# The runtime's rooms by rank (docs/architecture.md, "Rooms of the runtime").
ROOMS = {"model": 0, "solve": 1, "warp": 2, "contact": 3, "region": 3, "haptics": 4,
         "recording": 4, "scripted": 4, "tick": 5}
# Public runtime headers with no source of their own: their room.
PUBLIC_ROOMS = {"tool_geometry": "model", "contact_point": "contact"}
SOURCE_DIRS = ["lib", "precompute", "server", "clients", "viewer", "bench", "fuzz", "examples"]
EXTENSIONS = (".cpp", ".hpp", ".h", ".c")
INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"', re.M)


def files(root):
    for top in SOURCE_DIRS:
        for d, _, names in os.walk(os.path.join(root, top)):
            if "node_modules" in d or "/corpus" in d or "/reproducers" in d:
                continue
            for n in names:
                if n.endswith(EXTENSIONS):
                    yield os.path.relpath(os.path.join(d, n), root)


def include_dirs(root, path):
    """Where a file's quoted includes are looked for: its own folder, the
    layers' include and internal folders, and tests/ (support headers)."""
    dirs = [os.path.dirname(path)]
    lib = os.path.join(root, "lib")
    for layer in os.listdir(lib) if os.path.isdir(lib) else []:
        for sub in ("include", "internal", "src"):
            if os.path.isdir(os.path.join(lib, layer, sub)):
                dirs.append(os.path.join("lib", layer, sub))
    for extra in ("lib/include", "lib/src", "tests", "bench", "fuzz/support"):
        if os.path.isdir(os.path.join(root, extra)):
            dirs.append(extra)
    return dirs


def unit(path):
    return os.path.splitext(path)[0]


def layer_of(path):
    parts = path.split(os.sep)
    if parts[0] == "lib" and len(parts) > 1 and parts[1] in LAYERS:
        return parts[1]
    return None


def room_of(path, stem_unit):
    """The runtime room of a file of lib/runtime, or None for another layer.
    A public header is in the room of its unit's source."""
    parts = path.split(os.sep)
    if parts[:2] != ["lib", "runtime"]:
        return None
    if parts[2] == "src" and len(parts) > 4:
        return parts[3]
    if parts[2] == "internal" and len(parts) > 5:
        return parts[5]
    stem = os.path.basename(unit(path))
    source = stem_unit.get(stem)
    if source is not None and source != unit(path):
        return room_of(source + ".cpp", stem_unit)
    return PUBLIC_ROOMS.get(stem, "?")


def main(argv):
    check = "--check" in argv
    programs_as_one = "--programs-as-one" in argv
    args = [a for a in argv if not a.startswith("--")]
    root = os.path.abspath(args[0] if args else os.path.join(os.path.dirname(__file__), ".."))
    all_files = sorted(files(root))
    present = set(all_files)
    # A library header's unit is the unit of the .cpp of the same stem,
    # wherever it is; x_internal.hpp is part of x's unit.
    stem_unit = {}
    for f in all_files:
        if f.endswith((".cpp", ".c")):
            stem_unit[os.path.basename(unit(f))] = unit(f)
    def unit_of(f):
        if not f.startswith("lib"):
            return f.split(os.sep)[0] if programs_as_one else unit(f)
        stem = os.path.basename(unit(f))
        stem = stem[: -len("_internal")] if stem.endswith("_internal") else stem
        return stem_unit.get(stem, unit(f))

    edges = defaultdict(set)
    broken = []
    for f in all_files:
        text = open(os.path.join(root, f), encoding="utf-8", errors="replace").read()
        for inc in INCLUDE.findall(text):
            target = None
            for d in include_dirs(root, f):
                candidate = os.path.normpath(os.path.join(d, inc))
                if candidate in present:
                    target = candidate
                    break
            if target is None:
                continue  # generated (palpate.h, version.hpp) or a system header
            a, b = unit_of(f), unit_of(target)
            if a != b:
                edges[a].add(b)
            la, lb = layer_of(f), layer_of(target)
            if la and lb and (LAYERS[lb] > LAYERS[la] or (la, lb) in SIBLINGS):
                broken.append(f"{f} includes {target}: layer {la} may not include {lb}")
            ra, rb = room_of(f, stem_unit), room_of(target, stem_unit)
            if ra and rb:
                if "?" in (ra, rb) or ra not in ROOMS or rb not in ROOMS:
                    broken.append(f"{f} includes {target}: a runtime file outside the rooms "
                                  f"{sorted(ROOMS)} (a public header needs a source or an entry "
                                  f"in PUBLIC_ROOMS)")
                elif ra != rb and ROOMS[rb] >= ROOMS[ra]:
                    broken.append(f"{f} includes {target}: room {ra} (rank {ROOMS[ra]}) may not "
                                  f"include room {rb} (rank {ROOMS[rb]})")
            if la is None and lb and os.sep + "include" + os.sep not in target:
                broken.append(f"{f} includes {target}: programs include public headers only")

    units = {unit_of(f) for f in all_files}
    level = {}
    def depth(u, seen=()):
        if u in level:
            return level[u]
        if u in seen:
            return 1  # a cycle: counted once
        level[u] = 1 + max((depth(v, seen + (u,)) for v in edges[u]), default=0)
        return level[u]
    levels = max((depth(u) for u in units), default=0)
    lib_units = {u for u in units if u.startswith("lib" + os.sep)}
    lib_edges = sum(1 for u in lib_units for v in edges[u] if v in lib_units)
    print(f"units {len(units)} (library {len(lib_units)}), include edges "
          f"{sum(len(v) for v in edges.values())} (within the library {lib_edges}), levels {levels}")
    if broken:
        print(f"layer rule broken {len(broken)} time(s):")
        for b in broken:
            print("  " + b)
    else:
        print("layer rule kept: no include from a lower layer to a higher one, nor from a "
              "lower room of the runtime to a higher one")
    return 1 if (check and broken) else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
