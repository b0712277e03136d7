#!/usr/bin/env python3
"""No import circle between the top-level modules of a crate.

A module here is a file or folder directly under a crate's src/ (lib.rs
and main.rs excepted); module A uses B when A's code outside its tests
names `crate::B` (in a path or a `use crate::{...}` list). A circle
(A uses B, B uses A, through any chain) makes each module readable only
with the others; this check fails on any circle not listed in KNOWN, and
on a listed one that is gone (so the list can only shrink).

    python3 scripts/module-cycles.py          # from the repository root
"""

import os
import re
import sys

# Circles not yet taken apart, by crate: the modules of each.
KNOWN = {}


def modules(src):
    """The crate's top-level modules and the files of each."""
    mods = {}
    for folder, _, files in os.walk(src):
        for name in files:
            if not name.endswith(".rs"):
                continue
            rel = os.path.relpath(os.path.join(folder, name), src)
            top = rel[: -len(".rs")].split(os.sep)[0]
            if top not in ("lib", "main"):
                mods.setdefault(top, []).append(os.path.join(folder, name))
    return mods


def uses(mods):
    """Per module, the other modules its non-test code names."""
    edges = {m: set() for m in mods}
    for m, files in mods.items():
        for path in files:
            with open(path, encoding="utf-8") as f:
                code = f.read().split("#[cfg(test)]")[0]
            for line in code.splitlines():
                if line.strip().startswith("//"):
                    continue
                names = re.findall(r"crate::([a-z_0-9]+)", line)
                listed = re.search(r"use crate::\{([^}]*)", line)
                if listed:
                    names += re.findall(r"\b([a-z_0-9]+)\b", listed.group(1))
                edges[m].update(n for n in names if n in mods and n != m)
    return edges


def circles(edges):
    """The strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on, found = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(edges[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return sorted(found)


def main():
    root = os.getcwd()
    failures = []
    for crate in sorted(os.listdir(root)):
        src = os.path.join(root, crate, "src")
        if not (crate.startswith("fshape-") and os.path.isdir(src)):
            continue
        edges = uses(modules(src))
        found = circles(edges)
        known = sorted(sorted(c) for c in KNOWN.get(crate, []))
        for c in found:
            if c not in known:
                chain = "; ".join(f"{m} uses {', '.join(sorted(edges[m] & set(c)))}" for m in c)
                failures.append(f"{crate}: an import circle between {', '.join(c)} ({chain})")
        for c in known:
            if c not in found:
                failures.append(f"{crate}: the circle {', '.join(c)} is gone: remove it from KNOWN in {__file__}")
    for f in failures:
        print(f, file=sys.stderr)
    if not failures:
        print("no import circle inside a crate but the known ones:", sum(len(v) for v in KNOWN.values()))
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
