"""poseforest: body parts and 3D joint proposals from single depth images (Shotton et al. 2011).

    import numpy as np, poseforest
    forest = poseforest.Forest("forest.pff")
    labels = forest.classify(depth)          # depth: uint16 (height, width), millimetres
    probs = forest.distributions(depth)      # float32 (height, width, num_parts)
    joints = forest.joints(depth)            # structured array, see JOINT_NAMES
    stream = poseforest.SkeletonStream(forest)
    people = stream.process(depth, 0.0)      # per person: id, joints (position, tracked, ...)

Reference: docs/runtime/api.md (share/doc/poseforest/api.md when installed).
"""
from ._poseforest import JOINT_NAMES, Error, Forest, SkeletonStream, __version__

__all__ = ["Forest", "SkeletonStream", "Error", "JOINT_NAMES", "__version__"]
