#!/usr/bin/env python3
"""Checks that every #include "inhand/M/..." in a module's sources and headers names a module
that the including module depends on (src/CMakeLists.txt: inhand_module(NAME ... DEPS ...),
transitively), so that dependencies point one way. Prints the module graph with --graph.
Usage: scripts/check_includes.py [--graph] [--root DIR]   (exit 1 and each offending line
otherwise; DIR: another tree laid out as this one, default this repository)"""
import pathlib
import re
import sys

root = pathlib.Path(__file__).resolve().parent.parent
if "--root" in sys.argv:
    root = pathlib.Path(sys.argv[sys.argv.index("--root") + 1])
cmake = (root / "src" / "CMakeLists.txt").read_text()
deps = {}
for m in re.finditer(r"inhand_module\((\w+)(.*?)\)", cmake, re.S):
    body = m.group(2)
    d = re.search(r"\bDEPS\b(.*?)(?:\bPRIVATE_DEPS\b|$)", body, re.S)
    deps[m.group(1)] = re.findall(r"inhand::(\w+)", d.group(1)) if d else []


def closure(name, seen=None):
    seen = set() if seen is None else seen
    for d in deps.get(name, []):
        if d not in seen:
            seen.add(d)
            closure(d, seen)
    return seen


if "--graph" in sys.argv:
    for name, ds in deps.items():
        print(f"{name} -> {', '.join(ds) if ds else '(none)'}")
    sys.exit(0)

bad = []
for name in deps:
    allowed = closure(name) | {name}
    files = list((root / "src" / name).rglob("*")) + list((root / "include" / "inhand" / name).rglob("*"))
    for f in sorted(files):
        if f.suffix not in (".h", ".cc"):
            continue
        for n, line in enumerate(f.read_text().splitlines(), 1):
            inc = re.match(r'\s*#\s*include\s+"inhand/(\w+)/', line)
            if inc and inc.group(1) not in allowed:
                bad.append(f"{f.relative_to(root)}:{n}: {name} includes {inc.group(1)}, "
                           f"which it does not depend on ({', '.join(sorted(allowed - {name})) or 'nothing'})")
for b in bad:
    print(b)
if bad:
    print(f"check_includes: {len(bad)} includes against the module graph (src/CMakeLists.txt)")
sys.exit(1 if bad else 0)
