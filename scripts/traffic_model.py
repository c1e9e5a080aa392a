#!/usr/bin/python3
"""Traffic and coordinator-time model of the distributed training service (docs/distributed/traffic_model.md).

Fits two small models to the per-level rows that `build/bench/distributed --csv FILE` measured,
then projects them to the paper's scale (300k images per tree, 2000 pixels, 2000 candidates x 50
thresholds, 3 trees, depth 20: ~1M images) and beyond, with and without subtree hand-off.

  /usr/bin/python3 scripts/traffic_model.py MEASURED.csv

Models (per tree level d with n_d frontier nodes of s = S / n_d samples each, S = images x pixels
per tree, W workers, K candidates, B = thresholds + 1 bins, P = 31 parts, s_w = s / W samples of
a node on one worker):

  bytes_d = W * n_d * K * q(s_w)       reply bytes (ranges + histogram rounds) of level d
      q(s_w) = min(c * s_w^e, 2 * B * P, 12 + 3 * s_w): bytes per node, candidate and worker.
      c, e: a power law fitted (log-log least squares) to the measured levels; the caps are
      physical: a dense histogram costs at most one 2-byte varint per (bin, part) cell, and a
      sparse one at most ~3 bytes per sample (each sample is one count in one cell per
      candidate: zero-run, run length, value) plus the ranges round's min/max (~12 bytes).
  merge_d = a * bytes_d + b * n_d * K * B * min(P, s)
      decoding the replies + the split search over every node's dense histogram (fitted, >= 0).

Assumptions (stated in the doc): balanced trees (every frontier node splits until depth D, which
holds at the paper's scale: a depth-19 node still has ~1,100 samples), samples spread evenly
over workers, the coordinator merges on one core. Subtree hand-off with threshold T: a node
with s <= T samples is trained whole by one worker; it costs a SubtreeTask (the ids of the frames
holding its samples, 4 bytes each) and a SubtreeResult (16 bytes per internal node, 16 + 31
bytes per leaf) instead of histograms, and no merge; the worker re-renders the frames holding the
node's samples: images * (1 - exp(-s / images)) of them if the samples are spread evenly over the
frames (an upper estimate: pixels of one image that share a body part tend to share nodes).
"""

import csv
import math
import sys

P = 31


def bytes_per_node_candidate(s_w, bins, c, e):
    return min(c * s_w ** e, 2.0 * bins * P, 12.0 + 3.0 * s_w)


def frames_of(s, images):
    return images * (1.0 - math.exp(-s / images))


def lstsq2(xs, ys):
    """Least squares y = c0 * x0 + c1 * x1 (no intercept), coefficients clamped at >= 0."""
    s00 = sum(x[0] * x[0] for x in xs)
    s01 = sum(x[0] * x[1] for x in xs)
    s11 = sum(x[1] * x[1] for x in xs)
    t0 = sum(x[0] * y for x, y in zip(xs, ys))
    t1 = sum(x[1] * y for x, y in zip(xs, ys))
    det = s00 * s11 - s01 * s01
    if det <= 0:
        return (t0 / s00 if s00 else 0.0, 0.0)
    c0 = (t0 * s11 - t1 * s01) / det
    c1 = (s00 * t1 - s01 * t0) / det
    if c0 < 0:
        return (0.0, max(0.0, t1 / s11))
    if c1 < 0:
        return (max(0.0, t0 / s00), 0.0)
    return (c0, c1)


def load(path):
    rows = []
    with open(path) as f:
        for r in csv.DictReader(f):
            rows.append({k: float(v) for k, v in r.items()})
    return [r for r in rows if r["bytes_received"] > 0 and r["nodes"] > 0]


def fit(rows):
    """Returns c, e (bytes power law) and a, b (merge seconds per byte and per dense cell)."""
    lx, ly = [], []
    for r in rows:
        w, n, k = r["workers"], r["nodes"], r["candidates"]
        lx.append(math.log(r["samples"] / n / w))
        ly.append(math.log(r["bytes_received"] / (w * n * k)))
    mx, my = sum(lx) / len(lx), sum(ly) / len(ly)
    e = sum((x - mx) * (y - my) for x, y in zip(lx, ly)) / sum((x - mx) ** 2 for x in lx)
    c = math.exp(my - e * mx)
    # Merge: relative least squares (every level counts, not only the biggest).
    xs, ys = [], []
    for r in rows:
        n, k, b = r["nodes"], r["candidates"], r["bins"]
        s = r["samples"] / n
        scale = 1.0 / max(r["merge_s"], 1e-5)
        xs.append((r["bytes_received"] * scale, n * k * b * min(P, s) * scale))
        ys.append(1.0)
    a, bb = lstsq2(xs, ys)
    return c, e, a, bb


class Model:
    def __init__(self, c, e, a, b):
        self.c, self.e, self.a, self.b = c, e, a, b

    def level(self, d, images, px, K, B, W, T, D):
        """Level d of a tree: dict of histogram bytes, hand-off bytes, merge s, nodes, samples per
        node, state, frames re-rendered."""
        S = images * px
        n = 2 ** d
        s = S / n
        out = dict(hist=0.0, hand=0.0, merge=0.0, nodes=n, s=s, state="histograms", frames=0.0)
        if T and s <= T:
            if d > 0 and S / (n // 2) <= T:
                out["state"] = "inside subtrees"
                return out
            depth_left = D - d
            frames = frames_of(s, images)
            task = frames * 4 + d * 24 + 64
            result = (2 ** depth_left - 1) * 16 + 2 ** depth_left * (16 + P)
            out.update(hand=n * (task + result), state="handed off", frames=n * frames)
            return out
        hist = W * n * K * bytes_per_node_candidate(s / W, B, self.c, self.e)
        out.update(hist=hist, merge=self.a * hist + self.b * n * K * B * min(P, s))
        return out

    def tree(self, images, px, K, B, D, W, T):
        t = dict(hist=0.0, hand=0.0, merge=0.0, peak=0.0, frames=0.0)
        for d in range(D):
            lv = self.level(d, images, px, K, B, W, T, D)
            for key in ("hist", "hand", "merge", "frames"):
                t[key] += lv[key]
            t["peak"] = max(t["peak"], lv["hist"] + lv["hand"])
        return t


def human(b):
    for unit, f in (("PB", 1e15), ("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if b >= f:
            return "%.3g %s" % (b / f, unit)
    return "%.0f B" % b


def hms(s):
    if s >= 86400:
        return "%.3g d" % (s / 86400)
    if s >= 3600:
        return "%.3g h" % (s / 3600)
    if s >= 60:
        return "%.3g min" % (s / 60)
    return "%.3g s" % s


def table(header, rows):
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for r in rows:
        out.append("| " + " | ".join(str(c) for c in r) + " |")
    return "\n".join(out)


def main(argv):
    if len(argv) != 2 or argv[1] in ("-h", "--help"):
        print(__doc__)
        return 0 if len(argv) == 2 else 2
    try:
        rows = load(argv[1])
    except (OSError, KeyError, ValueError) as err:
        print("traffic_model: %s: %s (write it with build/bench/distributed --csv FILE)" % (argv[1], err),
              file=sys.stderr)
        return 1
    if len(rows) < 3:
        print("traffic_model: %s has %d per-level rows with bytes; need at least 3" % (argv[1], len(rows)),
              file=sys.stderr)
        return 1
    c, e, a, bb = fit(rows)
    model = Model(c, e, a, bb)
    print("## Fit on %d measured levels (%s)\n" % (len(rows), argv[1]))
    print("bytes per node, candidate and worker = %.3g * (samples per node and worker)^%.3f (capped); "
          "merge = %.3g s per received byte + %.3g s per dense histogram cell\n" % (c, e, a, bb))
    check, errs_b, errs_m = [], [], []
    for r in rows:
        w, n, k, b = r["workers"], r["nodes"], r["candidates"], r["bins"]
        s = r["samples"] / n
        mb = w * n * k * bytes_per_node_candidate(s / w, b, c, e)
        mm = a * r["bytes_received"] + bb * n * k * b * min(P, s)
        errs_b.append(abs(mb / r["bytes_received"] - 1))
        errs_m.append(abs(mm / max(r["merge_s"], 1e-5) - 1))
        check.append([int(w), int(r["tree"]), int(r["level"]), int(n), int(r["samples"]), human(r["bytes_received"]),
                      human(mb), "%.1f" % (r["merge_s"] * 1e3), "%.1f" % (mm * 1e3)])
    print(table(["workers", "tree", "level", "nodes", "samples", "bytes measured", "bytes model", "merge ms measured",
                 "merge ms model"], check))
    print("\nmedian relative error: bytes %.0f %%, merge %.0f %%\n" %
          (100 * sorted(errs_b)[len(errs_b) // 2], 100 * sorted(errs_m)[len(errs_m) // 2]))

    px, K, B, D, trees, T = 2000, 2000, 51, 20, 3, 50000
    print("## Paper scale: 300k images per tree (3 trees: ~1M images), 2000 pixels per image, 2000 candidates x "
          "50 thresholds, depth 20\n")
    print("Per level of one tree, 100 workers; left without hand-off, right with hand-off at T = %d samples:\n" % T)
    lv = []
    for d in range(D):
        x = model.level(d, 300000, px, K, B, 100, 0, D)
        y = model.level(d, 300000, px, K, B, 100, T, D)
        lv.append([d, x["nodes"], "%.3g" % x["s"], human(x["hist"]), hms(x["merge"]), y["state"],
                   human(y["hist"] + y["hand"]), hms(y["merge"])])
    print(table(["level", "nodes", "samples/node", "bytes", "merge", "with hand-off", "bytes", "merge"], lv))

    def totals_row(label, images, depth, W, thr):
        x = model.tree(images, px, K, B, depth, W, 0)
        y = model.tree(images, px, K, B, depth, W, thr)
        return [label, human(trees * x["hist"]), human(x["peak"]), hms(trees * x["merge"]),
                human(trees * (y["hist"] + y["hand"])), hms(trees * y["merge"]),
                "%.3g (%.0fx)" % (trees * y["frames"], y["frames"] / images)]

    hdr = ["bytes", "peak level", "coordinator merge", "bytes, hand-off T=%d" % T, "merge",
           "frames re-rendered (x images)"]
    print("\nWhole job (3 trees, 300k images per tree, depth 20) vs workers:\n")
    print(table(["workers"] + hdr, [totals_row(W, 300000, D, W, T) for W in (1, 10, 100, 1000)]))
    print("\nWhole job (3 trees, depth 20, 100 workers) vs images per tree:\n")
    print(table(["images per tree"] + hdr,
                [totals_row(i, i, D, 100, T) for i in (15000, 100000, 300000, 1000000, 3000000)]))
    print("\nWhole job (3 trees, 300k images per tree, 100 workers) vs depth:\n")
    print(table(["depth"] + hdr, [totals_row(d, 300000, d, 100, T) for d in (12, 16, 20, 24, 28)]))
    print("\nHand-off threshold T (3 trees, 300k images per tree, depth 20, 100 workers):\n")
    tt = []
    for thr in (0, 2000, 10000, 50000, 200000, 1000000):
        y = model.tree(300000, px, K, B, D, 100, thr)
        first = next((d for d in range(D) if thr and 300000 * px / 2 ** d <= thr), None)
        tt.append([thr if thr else "off", human(trees * (y["hist"] + y["hand"])), human(y["peak"]),
                   hms(trees * y["merge"]), "-" if first is None else first,
                   "-" if first is None else 2 ** first, "%.3g (%.0fx)" % (trees * y["frames"], y["frames"] / 300000)])
    print(table(["T (samples)", "bytes", "peak level", "merge", "hand-off level", "subtrees per tree",
                 "frames re-rendered (x images)"], tt))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
