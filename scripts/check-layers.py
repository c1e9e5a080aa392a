#!/usr/bin/env python3
"""Checks that each source folder includes only the folders below it in the layering.

The layers, bottom first (docs/architecture.md, ../shared/STYLE.md "Layers"):
    runtime      the inference library and its commands; depends on nothing heavier than Eigen (+ libspng/zlib)
    proto        the messages (Protobuf) and the DDS transport; includes the runtime
    renderer     synthetic depth frames (EGL, Assimp); includes the runtime
    engine       the training engine both services use; includes renderer, proto, runtime
    worker       the worker service; includes engine and below
    coordinator  the coordinator service; includes engine and below
The two services are siblings: neither includes the other (they share code only through the
engine and proto). bench/ and tests/ sit above everything and are not checked.

Usage: scripts/check-layers.py [--graph] [ROOT]
  --graph  also print the include graph between folders (counts of #include lines).
Exit status 1, naming every offending #include, when a folder includes one above it or beside it.
"""
import argparse
import collections
import os
import re
import sys

LAYERS = {"runtime": 0, "proto": 1, "renderer": 2, "engine": 3, "worker": 4, "coordinator": 4}
# Include paths that name no folder: headers generated from proto/poseforest/v1/*.proto, and the
# runtime library's public headers (runtime/api/include/poseforest/).
PREFIXES = (("poseforest/v1/", "proto"), ("poseforest/", "runtime"))
SOURCE_EXT = (".h", ".hpp", ".cpp", ".cc", ".c")
INCLUDE = re.compile(r'^\s*#\s*include\s*"([^"]+)"')


def folder_of(include, including_file, root):
    """The top-level folder an #include "..." names, or None for a system/local header."""
    first = include.split("/", 1)[0]
    if first in LAYERS and "/" in include:
        return first
    for prefix, folder in PREFIXES:
        if include.startswith(prefix):
            return folder
    # A path relative to the including file's folder stays in that folder.
    if os.path.exists(os.path.join(os.path.dirname(including_file), include)):
        return os.path.relpath(including_file, root).split(os.sep, 1)[0]
    return None


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--graph", action="store_true", help="print the include graph between folders")
    parser.add_argument("root", nargs="?", default=os.path.join(os.path.dirname(__file__), ".."))
    args = parser.parse_args()
    root = os.path.abspath(args.root)

    graph = collections.Counter()
    violations = []
    for layer in LAYERS:
        top = os.path.join(root, layer)
        for dirpath, _, files in os.walk(top):
            for name in sorted(files):
                if not name.endswith(SOURCE_EXT):
                    continue
                path = os.path.join(dirpath, name)
                with open(path, encoding="utf-8", errors="replace") as f:
                    for lineno, line in enumerate(f, 1):
                        m = INCLUDE.match(line)
                        if not m:
                            continue
                        target = folder_of(m.group(1), path, root)
                        if target is None or target == layer:
                            continue
                        graph[(layer, target)] += 1
                        if LAYERS[target] >= LAYERS[layer]:
                            rel = os.path.relpath(path, root)
                            violations.append(f"{rel}:{lineno}: {layer}/ includes {m.group(1)} "
                                              f"({target}/ is not below {layer}/)")
    if args.graph:
        print("include graph between folders (#include lines):")
        for (src, dst), n in sorted(graph.items(), key=lambda kv: (-LAYERS[kv[0][0]], kv[0])):
            mark = "" if LAYERS[dst] < LAYERS[src] else "   <-- not allowed"
            print(f"  {src:12s} -> {dst:12s} {n:4d}{mark}")
    if violations:
        print(f"layering: {len(violations)} include(s) against the layering "
              "(runtime < proto < renderer < engine < worker, coordinator):", file=sys.stderr)
        for v in violations:
            print("  " + v, file=sys.stderr)
        return 1
    print("layering: ok (runtime < proto < renderer < engine < worker, coordinator)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
