#!/usr/bin/env python3
# The skeleton accuracy table of `poseforest eval` (docs/runtime/live.md) from `poseforest live --jsonl F`
# on a render folder's depth PNGs (one person per frame): skeleton_accuracy_from_live.py F RENDERS.
import json, sys, math
names = ["head","neck","L_shoulder","R_shoulder","L_elbow","R_elbow","L_wrist","R_wrist","L_hand","R_hand",
         "L_knee","R_knee","L_ankle","R_ankle","L_foot","R_foot"]
D = 0.1
vis = {n: 0 for n in names}; within = dict(vis); tracked = dict(vis); right = dict(vis); untr = dict(vis); untr_inv = dict(vis)
frames = 0
for line in open(sys.argv[1]):
    f = json.loads(line)
    src = f["source"]
    k = int(src.split("depth_")[1].split(".")[0])
    truth = json.load(open(f"{sys.argv[2]}/joints_{k:06d}.json"))["people"]
    if len(truth) != 1 or len(f["people"]) != 1: continue
    frames += 1
    tj = {j["name"]: j for j in truth[0]["joints"]}
    for j in f["people"][0]["joints"]:
        n = j["name"]; t = tj[n]
        near = j["position_m"] is not None and math.dist(j["position_m"], (t["x"], t["y"], t["z"])) <= D
        v = t["visible"]
        vis[n] += v; within[n] += v and j["tracked"] and near; tracked[n] += j["tracked"]
        right[n] += j["tracked"] and near; untr[n] += not j["tracked"]; untr_inv[n] += (not j["tracked"]) and not v
r = lambda a, b: a / b if b else None
print(f"{frames} one-person frames")
print(f"{'joint':11s} {'visible':>7s} {'within':>7s} {'right':>7s} {'untr_ok':>7s}")
m = [[], [], []]
for n in names:
    a, b, c = r(within[n], vis[n]), r(right[n], tracked[n]), r(untr_inv[n], untr[n])
    for lst, x in zip(m, (a, b, c)):
        if x is not None: lst.append(x)
    fmt = lambda x: "-" if x is None else f"{x:.3f}"
    print(f"{n:11s} {vis[n]:7d} {fmt(a):>7s} {fmt(b):>7s} {fmt(c):>7s}")
print("mean", *(f"{sum(l)/len(l):.3f}" for l in m))
