#!/usr/bin/python3
"""The scikit-learn side of bench/train's side by side.

Fits one tree of scikit-learn's ExtraTreesClassifier (default; --model forest: RandomForestClassifier,
best split) on a precomputed feature matrix and times fit() alone. bench/train writes the matrix: the
responses of its sampled pixels to the root node's candidate features (N x K float32) and their part
labels (N uint8). Every candidate is considered at every node (max_features=None), entropy criterion,
the same max_depth and min_samples_split as our engine, no bootstrap, n_jobs=1.

Prints one line:
  sklearn: model=... fit_cpu_s=... fit_wall_s=... nodes=... depth=... train_accuracy=... version=...
Run with /usr/bin/python3 (Debian's python3-sklearn), e.g.
  /usr/bin/python3 bench/sklearn_side_by_side.py --x x.npy --y y.npy --depth 20
"""
import argparse
import sys
import time


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--x", required=True, help="N x K float32 .npy: feature responses")
    ap.add_argument("--y", required=True, help="N uint8 .npy: part labels")
    ap.add_argument("--depth", type=int, required=True, help="max_depth")
    ap.add_argument("--min-samples-split", type=int, default=10)
    ap.add_argument("--model", choices=["extra", "forest"], default="extra")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    try:
        import numpy as np
        import sklearn
        from sklearn.ensemble import ExtraTreesClassifier, RandomForestClassifier
    except ImportError as e:
        print(f"sklearn_side_by_side: {e} (Debian: apt-get install python3-sklearn; run with /usr/bin/python3)",
              file=sys.stderr)
        return 2
    try:
        x = np.load(a.x)
        y = np.load(a.y)
    except (OSError, ValueError) as e:
        print(f"sklearn_side_by_side: cannot read the matrix: {e}", file=sys.stderr)
        return 2
    if x.dtype != np.float32 or x.ndim != 2 or y.ndim != 1 or y.shape[0] != x.shape[0] or x.shape[0] == 0:
        print(f"sklearn_side_by_side: {a.x}: expected N x K float32 and {a.y}: N labels, got {x.dtype} {x.shape} "
              f"and {y.dtype} {y.shape}", file=sys.stderr)
        return 2
    common = dict(n_estimators=1, criterion="entropy", max_depth=a.depth, max_features=None,
                  min_samples_split=a.min_samples_split, bootstrap=False, n_jobs=1, random_state=a.seed)
    model = ExtraTreesClassifier(**common) if a.model == "extra" else RandomForestClassifier(**common)
    c0, w0 = time.process_time(), time.perf_counter()
    model.fit(x, y)
    fit_cpu, fit_wall = time.process_time() - c0, time.perf_counter() - w0
    tree = model.estimators_[0].tree_
    accuracy = model.score(x, y)
    print(f"sklearn: model={type(model).__name__} fit_cpu_s={fit_cpu:.3f} fit_wall_s={fit_wall:.3f} "
          f"nodes={tree.node_count} depth={tree.max_depth} train_accuracy={accuracy:.4f} "
          f"version={sklearn.__version__}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
