#!/usr/bin/env python3
"""Per-level wall time of the same job trained by the engine and by the service, from their event logs.

    scripts/level-table.py ENGINE.jsonl SERVICE.jsonl   (the --event-log of `poseforest train JOB
                                                       --threads N` and of `poseforest train JOB
                                                       --local-workers N`)

Prints a Markdown table: per tree and level (the LEVEL_DONE events), frontier nodes, the engine's
level seconds (frame loading left out), the service's level seconds, their ratio, the reply bytes
the coordinator received, its merge time and the subtree tasks it handed off; then totals. A level
logged twice by the service (a resumed run) counts once, the later one.

Then, when the service's events have them (`rounds` and the rest, since 27 Nov 2026), a second
table: where the service's level time went. Per level: the request/reply rounds split into the
critical worker's computing, the time its request waited while it was busy (subtree tasks) and
traffic (the rest: wire, encoding, decoding); the coordinator's merge; waiting for the level's
subtree results after the rounds; other (hand-off planning, decisions, checkpoint); and, summed
over the workers (they overlap the above), their subtree-task time and rendering.
"""
import json
import sys


def levels(path):
    """(tree, level) -> the LEVEL_DONE event (a dict) of the JSON Lines event log at `path`."""
    out = {}
    for line in open(path, errors="replace"):
        try:
            e = json.loads(line)
        except ValueError:
            continue
        if isinstance(e, dict) and e.get("event") == "LEVEL_DONE":
            out[(int(e.get("tree", 0)), int(e.get("level", 0)))] = e
    return out


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    eng, svc = levels(sys.argv[1]), levels(sys.argv[2])
    print("| tree | level | nodes | engine s | service s | service / engine | received MiB | merge s | subtrees handed off |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    te = ts = 0.0
    for key in sorted(set(eng) | set(svc)):
        e = eng.get(key)
        s = svc.get(key)
        es = e.get("seconds", 0.0) if e else None
        ss = s.get("seconds", 0.0) if s else None
        te += es or 0
        ts += ss or 0
        ratio = f"{ss / es:.2f}" if es and ss else ""
        received = "" if s is None else f"{s.get('bytes_received', 0) / (1 << 20):.1f}"
        merge = "" if s is None else f"{s.get('merge_seconds', 0):.2f}"
        tasks = "" if s is None else s.get("subtree_tasks", 0)
        print(f"| {key[0]} | {key[1]} | {(e or s).get('nodes', 0)} | {'' if es is None else f'{es:.1f}'} | "
              f"{'' if ss is None else f'{ss:.1f}'} | {ratio} | {received} | {merge} | {tasks} |")
    print(f"\nlevel time in all: engine {te:.0f} s, service {ts:.0f} s, service / engine {ts / te if te else 0:.2f}")
    # Levels decided by subtree results alone (no rounds, no waiting, no subtree work) have no split,
    # as the coordinator prints none for them.
    split = {k: v for k, v in svc.items() if "rounds" in v and (
        v["rounds"] > 0 or v.get("subtree_wait_seconds", 0) > 0 or v.get("subtree_busy_seconds", 0) > 0)}
    if not split:
        return
    print("\nWhere the service's level time went (s; the last two columns: summed over the workers, "
          "overlapping the others):\n")
    print("| tree | level | level s | rounds | worker computing | busy before it | traffic | merge | "
          "waiting for subtrees | other | workers: subtrees | workers: rendering |")
    print("|" + "---:|" * 12)
    names = ["seconds", "round_seconds", "compute_seconds", "queued_seconds", "traffic_seconds", "merge_seconds",
             "subtree_wait_seconds", "other", "subtree_busy_seconds", "render_seconds"]
    tot = [0.0] * len(names)
    for key in sorted(split):
        e = split[key]
        f = {n: float(e.get(n, 0.0)) for n in names}
        f["other"] = f["seconds"] - f["round_seconds"] - f["merge_seconds"] - f["subtree_wait_seconds"]
        tot = [a + f[n] for a, n in zip(tot, names)]
        print(f"| {key[0]} | {key[1]} | {f['seconds']:.1f} | {f['round_seconds']:.1f} ({int(e['rounds'])}) | "
              f"{f['compute_seconds']:.1f} | {f['queued_seconds']:.1f} | {f['traffic_seconds']:.1f} | "
              f"{f['merge_seconds']:.2f} | {f['subtree_wait_seconds']:.1f} | {f['other']:.1f} | "
              f"{f['subtree_busy_seconds']:.1f} | {f['render_seconds']:.1f} |")
    print("| all | | " + " | ".join(f"{t:.1f}" if n == "merge_seconds" else f"{t:.0f}" for t, n in zip(tot, names)) + " |")


if __name__ == "__main__":
    main()
