#!/usr/bin/env python3
"""Per-level wall time of the same job trained by the engine and by the service, from their logs.

    scripts/level-table.py ENGINE.log SERVICE.log     (the output of `poseforest train JOB --threads N`
                                                     and of `poseforest train JOB --local-workers N`)

Prints a Markdown table: per tree and level, frontier nodes, the engine's level seconds (its
elapsed column, differenced), the service's level seconds, their ratio, the reply bytes the
coordinator received, its merge time and the subtree tasks it handed off; then totals. Lines of
a level logged twice by the service (a resumed run) count once, the later one.

Then, when the service's log has them (its "  time:" line under each level, since 25 Nov 2026),
a second table: where the service's level time went. Per level: the request/reply rounds split
into the critical worker's computing, the time its request waited while it was busy (subtree
tasks) and traffic (the rest: wire, encoding, decoding); the coordinator's merge; waiting for
the level's subtree results after the rounds; other (hand-off planning, decisions, checkpoint);
and, summed over the workers (they overlap the above), their subtree-task time and rendering.
"""
import re
import sys

ENGINE = re.compile(r"^tree (\d+) level\s+(\d+):\s+(\d+) nodes .*?evaluations/s, ([0-9.]+) s,")
ENGINE_TREE = re.compile(r"^tree (\d+): \d+ samples from .* loaded in ([0-9.]+) s")
SERVICE = re.compile(
    r"^tree (\d+) level (\d+): (\d+) nodes .*? received, .*? sent, merge ([0-9.]+) ms, level ([0-9.]+) s(.*)$")
TIME = re.compile(
    r"^time: (\d+) rounds ([0-9.]+) s \(worker computing ([0-9.]+) s, busy before it ([0-9.]+) s, traffic "
    r"([0-9.]+) s\), merge ([0-9.]+) s, waiting for subtrees ([0-9.]+) s, other ([0-9.]+) s; workers: subtrees "
    r"([0-9.]+) s, rendering ([0-9.]+) s")
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


def service_levels(path, split=None):
    """(tree, level) -> (nodes, seconds, received bytes, merge ms, subtree tasks); `split`, if
    given, gets (tree, level) -> the figures of the level's "time:" line."""
    levels = {}
    last = None
    for line in open(path, errors="replace"):
        m = TIME.match(line.strip())
        if m and last is not None and split is not None:
            split[last] = [float(g) for g in m.groups()]
            continue
        m = SERVICE.match(line.strip())
        if not m:
            continue
        last = (int(m.group(1)), int(m.group(2)))
        t, lv, nodes = int(m.group(1)), int(m.group(2)), int(m.group(3))
        rec = re.search(r"([0-9.]+) (B|KiB|MiB|GiB) received", line)
        received = float(rec.group(1)) * UNITS[rec.group(2)] if rec else 0.0
        tasks = re.search(r"(\d+) subtrees handed off", m.group(6))
        levels[(t, lv)] = (nodes, float(m.group(5)), received, float(m.group(4)), int(tasks.group(1)) if tasks else 0)
    return levels


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    split = {}
    eng, svc = engine_levels(sys.argv[1]), service_levels(sys.argv[2], split)
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
    if not split:
        return
    print("\nWhere the service's level time went (s; the last two columns: summed over the workers, "
          "overlapping the others):\n")
    print("| tree | level | level s | rounds | worker computing | busy before it | traffic | merge | "
          "waiting for subtrees | other | workers: subtrees | workers: rendering |")
    print("|" + "---:|" * 12)
    tot = [0.0] * 10
    for key in sorted(split):
        f = split[key]
        level_s = svc[key][1] if key in svc else 0.0
        tot = [a + b for a, b in zip(tot, [level_s] + f[1:])]
        print(f"| {key[0]} | {key[1]} | {level_s:.1f} | {f[1]:.1f} ({int(f[0])}) | {f[2]:.1f} | {f[3]:.1f} | "
              f"{f[4]:.1f} | {f[5]:.2f} | {f[6]:.1f} | {f[7]:.1f} | {f[8]:.1f} | {f[9]:.1f} |")
    print(f"| all | | {tot[0]:.0f} | {tot[1]:.0f} | {tot[2]:.0f} | {tot[3]:.0f} | {tot[4]:.0f} | {tot[5]:.1f} | "
          f"{tot[6]:.0f} | {tot[7]:.0f} | {tot[8]:.0f} | {tot[9]:.0f} |")


if __name__ == "__main__":
    main()
