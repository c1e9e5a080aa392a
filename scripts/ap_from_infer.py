#!/usr/bin/env python3
# Section 4 AP per joint and mAP (D = 0.1 m, all-point interpolation) from `poseforest infer --joints
# --out-dir OUT` on a `poseforest render` folder: ap_from_infer.py OUT RENDERS. Scores as engine/
# evaluation (runtime::JointApEvaluator) does; docs/runtime/live.md used it for --pixel-stride 2.
import json, sys, math, glob
names = ["head","neck","L_shoulder","R_shoulder","L_elbow","R_elbow","L_wrist","R_wrist","L_hand","R_hand",
         "L_knee","R_knee","L_ankle","R_ankle","L_foot","R_foot"]
D = 0.1
scored = {n: [] for n in names}; pos = {n: 0 for n in names}
for f in sorted(glob.glob(sys.argv[1] + "/depth_*.joints.json")):
    k = int(f.split("depth_")[1].split(".")[0])
    people = json.load(open(f"{sys.argv[2]}/joints_{k:06d}.json"))["people"]
    props = {j["joint"]: j["proposals"] for j in json.load(open(f))["joints"]}
    for n in names:
        truth = [next(j for j in p["joints"] if j["name"] == n) for p in people]
        pos[n] += sum(t["visible"] for t in truth)
        matched = [False] * len(truth)
        for p in props[n]:
            best, bd = -1, 1e9
            for i, t in enumerate(truth):
                d = math.dist(p["position_m"], (t["x"], t["y"], t["z"]))
                if d < bd: best, bd = i, d
            if best < 0 or bd > D: scored[n].append((p["confidence"], False)); continue
            if not truth[best]["visible"]: continue
            if matched[best]: scored[n].append((p["confidence"], False))
            else: matched[best] = True; scored[n].append((p["confidence"], True))
def ap(s, npos):
    if npos == 0: return None
    s = sorted(s, key=lambda x: -x[0]); tp = fp = 0; prec = []; rec = []
    for c, t in s:
        tp += t; fp += not t; prec.append(tp / (tp + fp)); rec.append(tp / npos)
    area = 0; prev_r = 0
    for i in range(len(s)):
        p = max(prec[i:]); area += (rec[i] - prev_r) * p; prev_r = rec[i]
    return area
aps = {n: ap(scored[n], pos[n]) for n in names}
for n in names: print(f"{n:11s} {aps[n]:.3f}")
v = [a for a in aps.values() if a is not None]
print(f"mAP {sum(v)/len(v):.3f}")
