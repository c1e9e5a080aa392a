#!/usr/bin/env python3
"""Checks that each source folder includes only the folders below it in the layering, and the
system libraries of its layer and below.

The layers, bottom first (docs/architecture.md, ../shared/STYLE.md "Layers"):
    runtime      the inference library and its public API; depends on nothing heavier than Eigen
                 and OpenMP (+ libspng/zlib for PNG files)
    proto        the messages (Protobuf), the DDS transport (Fast DDS) and the services' HTTP
                 server (cpp-httplib); includes the runtime
    renderer     synthetic depth frames (EGL, GLES, Assimp); includes the runtime
    engine       the training engine both services use; includes renderer, proto, runtime
    worker       the worker service; includes engine and below
    coordinator  the coordinator service; includes engine and below
    apps         the `poseforest` program: main, every command, the camera back ends (libfreenect,
                 OpenNI2), the live page, the ROS 2 publisher; includes everything
The two services are siblings: neither includes the other (they share code only through the
engine and proto). Nothing includes apps/. bench/ and tests/ sit above everything and are not
checked.

Project headers: an #include "folder/..." names the folder (generated poseforest/v1/*.pb.h count
as proto/, the public poseforest/*.h of runtime/api as runtime/); it must be a folder below the
including one.

System headers: an #include <...> of a library below the layer that owns it is refused. The rule
table (SYSTEM_RULES; a rule matches a header path that starts with one of its prefixes):
    library          header paths (prefixes)                                  lowest layer
    Fast DDS         fastdds/ fastrtps/ fastcdr/                              proto
    Protobuf         google/protobuf/                                         proto
    cpp-httplib      httplib.h                                                proto
    EGL/GLES         EGL/ KHR/ GLES/ GLES2/ GLES3/                            renderer
    Assimp           assimp/                                                  renderer
    libfreenect      libfreenect.h libfreenect/ libfreenect_                  apps
    OpenNI2          OpenNI.h, OpenNI2's Oni*.h / PS1080.h / PSLink.h, openni2/  apps
"Lowest layer" means that layer and every layer above it may include the library (the runtime
may include none of them: a runtime-only build needs a compiler, Eigen and OpenMP).

Usage: scripts/check-layers.py [--graph] [ROOT]
  --graph  also print the include graph between folders (counts of #include lines) and which
           folders include the libraries of the rule table.
Exit status 1, naming every offending #include, when a folder includes one above it or beside it,
or a library below its layer.
"""
import argparse
import collections
import os
import re
import sys

LAYERS = {"runtime": 0, "proto": 1, "renderer": 2, "engine": 3, "worker": 4, "coordinator": 4, "apps": 5}
ORDER = "runtime < proto < renderer < engine < worker, coordinator < apps"
# Include paths that name no folder: headers generated from proto/poseforest/v1/*.proto, and the
# runtime library's public headers (runtime/api/include/poseforest/).
PREFIXES = (("poseforest/v1/", "proto"), ("poseforest/", "runtime"))
# (library, header path prefixes, the lowest layer that may include it); see the docstring.
SYSTEM_RULES = (
    ("Fast DDS", ("fastdds/", "fastrtps/", "fastcdr/"), "proto"),
    ("Protobuf", ("google/protobuf/",), "proto"),
    ("cpp-httplib", ("httplib.h",), "proto"),
    ("EGL/GLES", ("EGL/", "KHR/", "GLES/", "GLES2/", "GLES3/"), "renderer"),
    ("Assimp", ("assimp/",), "renderer"),
    ("libfreenect", ("libfreenect.h", "libfreenect/", "libfreenect_"), "apps"),
    ("OpenNI2", ("OpenNI.h", "OniCAPI.h", "OniCEnums.h", "OniCProperties.h", "OniCTypes.h", "OniEnums.h",
                 "OniPlatform.h", "OniProperties.h", "OniVersion.h", "PS1080.h", "PSLink.h", "openni2/",
                 "OpenNI2/"), "apps"),
)
SOURCE_EXT = (".h", ".hpp", ".cpp", ".cc", ".c")
INCLUDE = re.compile(r'^\s*#\s*include\s*"([^"]+)"')
SYSTEM_INCLUDE = re.compile(r'^\s*#\s*include\s*<([^>]+)>')


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


def system_rule(header):
    """The rule of SYSTEM_RULES an #include <...> falls under, or None."""
    for rule in SYSTEM_RULES:
        if header.startswith(rule[1]):
            return rule
    return None


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--graph", action="store_true", help="print the include graph between folders")
    parser.add_argument("root", nargs="?", default=os.path.join(os.path.dirname(__file__), ".."))
    args = parser.parse_args()
    root = os.path.abspath(args.root)

    graph = collections.Counter()
    libraries = collections.Counter()
    violations = []
    for layer in LAYERS:
        top = os.path.join(root, layer)
        for dirpath, _, files in os.walk(top):
            for name in sorted(files):
                if not name.endswith(SOURCE_EXT):
                    continue
                path = os.path.join(dirpath, name)
                rel = os.path.relpath(path, root)
                with open(path, encoding="utf-8", errors="replace") as f:
                    for lineno, line in enumerate(f, 1):
                        m = SYSTEM_INCLUDE.match(line)
                        if m:
                            rule = system_rule(m.group(1))
                            if rule is None:
                                continue
                            library, _, lowest = rule
                            libraries[(layer, library)] += 1
                            if LAYERS[layer] < LAYERS[lowest]:
                                violations.append(f"{rel}:{lineno}: {layer}/ includes <{m.group(1)}> "
                                                  f"({library} is for {lowest}/ and above)")
                            continue
                        m = INCLUDE.match(line)
                        if not m:
                            continue
                        target = folder_of(m.group(1), path, root)
                        if target is None or target == layer:
                            continue
                        graph[(layer, target)] += 1
                        if LAYERS[target] >= LAYERS[layer]:
                            violations.append(f"{rel}:{lineno}: {layer}/ includes {m.group(1)} "
                                              f"({target}/ is not below {layer}/)")
    if args.graph:
        print("include graph between folders (#include lines):")
        for (src, dst), n in sorted(graph.items(), key=lambda kv: (-LAYERS[kv[0][0]], kv[0])):
            mark = "" if LAYERS[dst] < LAYERS[src] else "   <-- not allowed"
            print(f"  {src:12s} -> {dst:12s} {n:4d}{mark}")
        print("libraries of the rule table (#include <...> lines):")
        lowest = {rule[0]: rule[2] for rule in SYSTEM_RULES}
        for (src, lib), n in sorted(libraries.items(), key=lambda kv: (-LAYERS[kv[0][0]], kv[0])):
            mark = "" if LAYERS[src] >= LAYERS[lowest[lib]] else "   <-- not allowed"
            print(f"  {src:12s} -> {lib:12s} {n:4d}{mark}")
    if violations:
        print(f"layering: {len(violations)} include(s) against the layering ({ORDER}):", file=sys.stderr)
        for v in violations:
            print("  " + v, file=sys.stderr)
        return 1
    print(f"layering: ok ({ORDER}; system libraries at their layers)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
