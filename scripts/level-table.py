#!/usr/bin/env python3
"""Per-level wall time of the same job trained by the engine and by the service, from their logs.

    scripts/level-table.py ENGINE.log SERVICE.log     (the output of `poseforest train JOB --threads N`
                                                     and of `poseforest train JOB --local-workers N`)

Prints a Markdown table: per tree and level, frontier nodes, the engine's level seconds (its
elapsed column, differenced), the service's level seconds, their ratio, the reply bytes the
coordinator received, its merge time and the subtree tasks it handed off; then totals. Lines of
a level logged twice by the service (a resumed run) count once, the later one.
"""
import re
import sys

ENGINE = re.compile(r"^tree (\d+) level\s+(\d+):\s+(\d+) nodes .*?evaluations/s, ([0-9.]+) s,")
ENGINE_TREE = re.compile(r"^tree (\d+): \d+ samples from .* loaded in ([0-9.]+) s")
SERVICE = re.compile(
    r"^tree (\d+) level (\d+): (\d+) nodes .*? received, .*? sent, merge ([0-9.]+) ms, level ([0-9.]+) s(.*)$")
UNITS = {"B": 1, "KiB": 1 << 10, "MiB": 1 << 20, "GiB": 1 << 30}


def engine_levels(path):
    """(tree, level) -> (nodes, seconds). The engine prints seconds elapsed since the run began;
    a tree's frame loading (its "loaded in S s" line) is not part of its first level."""
    levels, last = {}, 0.0
    for line in open(path, errors="replace"):
        m = ENGINE_TREE.match(line)
        if m:
            last += float(m.group(2))
            continue
        m = ENGINE.match(line)
        if m:
            elapsed = float(m.group(4))
            levels[(int(m.group(1)), int(m.group(2)))] = (int(m.group(3)), elapsed - last)
            last = elapsed
    return levels


def service_levels(path):
    levels = {}
    for line in open(path, errors="replace"):
        m = SERVICE.match(line.strip())
        if not m:
            continue
        t, lv, nodes = int(m.group(1)), int(m.group(2)), int(m.group(3))
        rec = re.search(r"([0-9.]+) (B|KiB|MiB|GiB) received", line)
        received = float(rec.group(1)) * UNITS[rec.group(2)] if rec else 0.0
        tasks = re.search(r"(\d+) subtrees handed off", m.group(6))
        levels[(t, lv)] = (nodes, float(m.group(5)), received, float(m.group(4)), int(tasks.group(1)) if tasks else 0)
    return levels


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    eng, svc = engine_levels(sys.argv[1]), service_levels(sys.argv[2])
    print("| tree | level | nodes | engine s | service s | service / engine | received MiB | merge s | subtrees handed off |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    te = ts = 0.0
    for key in sorted(set(eng) | set(svc)):
        e = eng.get(key)
        s = svc.get(key)
        es = e[1] if e else None
        ss = s[1] if s else None
        te += es or 0
        ts += ss or 0
        ratio = f"{ss / es:.2f}" if es and ss else ""
        print(f"| {key[0]} | {key[1]} | {(e or s)[0]} | {'' if es is None else f'{es:.1f}'} | "
              f"{'' if ss is None else f'{ss:.1f}'} | {ratio} | {'' if s is None else f'{s[2] / (1 << 20):.1f}'} | "
              f"{'' if s is None else f'{s[3] / 1e3:.2f}'} | {'' if s is None else s[4]} |")
    print(f"\nlevel time in all: engine {te:.0f} s, service {ts:.0f} s, service / engine {ts / te if te else 0:.2f}")


if __name__ == "__main__":
    main()
