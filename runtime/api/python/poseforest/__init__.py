"""poseforest: body parts and 3D joint proposals from single depth images (Shotton et al. 2011).

    import numpy as np, poseforest
    forest = poseforest.Forest("forest.pff")
    labels = forest.classify(depth)          # depth: uint16 (height, width), millimetres
    probs = forest.distributions(depth)      # float32 (height, width, num_parts)
    joints = forest.joints(depth)            # structured array, see JOINT_NAMES

Skeletons and segmentation are not in the runtime yet, so not here either.
Reference: docs/runtime/api.md (share/doc/poseforest/api.md when installed).
"""
from ._poseforest import JOINT_NAMES, Error, Forest, __version__

__all__ = ["Forest", "Error", "JOINT_NAMES", "__version__"]
