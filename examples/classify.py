"""Classifies a raw 640x480 depth frame (little-endian uint16 millimetres) with the Python module
and prints the body parts found and each joint's most confident proposal; optionally writes the
labels (one byte per pixel).
    PYTHONPATH=P/lib/python3/dist-packages python3 classify.py FOREST.pff DEPTH.raw [LABELS_OUT]
Run by the tests (tests/runtime)."""
import sys

import numpy as np
import poseforest

forest_path, depth_path = sys.argv[1], sys.argv[2]
depth = np.fromfile(depth_path, dtype="<u2").reshape(480, 640)
forest = poseforest.Forest(forest_path)
print(f"poseforest {poseforest.__version__}: {forest.num_trees} trees, {forest.num_parts} parts")
labels = forest.classify(depth)
counts = np.bincount(labels[labels != 255], minlength=forest.num_parts)
print("parts:", " ".join(f"{forest.part_names[p]}={n}" for p, n in enumerate(counts) if n))
if forest.has_joints:
    joints = forest.joints(depth)  # grouped by joint, most confident first
    for j in np.unique(joints["joint"]):
        best = joints[joints["joint"] == j][0]
        x, y, z = best["position_m"]
        print(f"  {poseforest.JOINT_NAMES[j]:<11} ({x:.3f}, {y:.3f}, {z:.3f}) m, confidence {best['confidence']:.4g}")
if len(sys.argv) > 3:
    labels.tofile(sys.argv[3])
