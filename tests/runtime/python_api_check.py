"""The Python module against the `poseforest` program, run by tests/runtime/consumers.sh with
PYTHONPATH at the install prefix:
    python3 python_api_check.py INPUTS POSEFOREST_PROGRAM VERSION
INPUTS holds make_api_inputs' files and cli/ the program's outputs for person.raw
(`infer --labels --distributions --joints`). Exits non-zero naming the first difference."""
import json
import subprocess
import sys
import threading
import time
import zlib
from pathlib import Path

import numpy as np
import poseforest

inputs, program, version = Path(sys.argv[1]), sys.argv[2], sys.argv[3]
checks = 0


def check(cond, what):
    global checks
    if not cond:
        sys.exit(f"FAIL: {what}")
    checks += 1
    print(f"ok: {what}")


def png_grey8(path):
    """The samples of an 8-bit greyscale PNG (what `infer --labels` writes), all five filters."""
    data = path.read_bytes()
    pos, idat, width, height = 8, b"", 0, 0
    while pos < len(data):
        n = int.from_bytes(data[pos:pos + 4], "big")
        kind, body = data[pos + 4:pos + 8], data[pos + 8:pos + 8 + n]
        if kind == b"IHDR":
            width, height = int.from_bytes(body[0:4], "big"), int.from_bytes(body[4:8], "big")
            assert body[8] == 8 and body[9] == 0, "not 8-bit greyscale"
        elif kind == b"IDAT":
            idat += body
        pos += 12 + n
    raw = zlib.decompress(idat)
    out = np.zeros((height, width), np.uint8)
    prior = np.zeros(width, np.int32)
    for y in range(height):
        f, line = raw[y * (width + 1)], np.frombuffer(raw, np.uint8, width, y * (width + 1) + 1).astype(np.int32)
        row = np.zeros(width, np.int32)
        for x in range(width):
            a = row[x - 1] if x else 0
            b = prior[x]
            c = prior[x - 1] if x else 0
            if f == 0:
                pred = 0
            elif f == 1:
                pred = a
            elif f == 2:
                pred = b
            elif f == 3:
                pred = (a + b) // 2
            else:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                pred = a if pa <= pb and pa <= pc else (b if pb <= pc else c)
            row[x] = (line[x] + pred) & 0xFF
        out[y] = row
        prior = row
    return out


depth = np.fromfile(inputs / "person.raw", dtype="<u2").reshape(480, 640)
forest = poseforest.Forest(str(inputs / "forest.pff"))
check(poseforest.__version__ == version, f"poseforest.__version__ == {version}")
check(forest.num_parts == 31 and forest.num_trees >= 1 and forest.has_joints, "forest properties")
check(len(poseforest.JOINT_NAMES) == 16 and poseforest.JOINT_NAMES[0] == "head", "JOINT_NAMES")

# Labels and distributions equal the program's files byte for byte.
labels = forest.classify(depth)
check(labels.dtype == np.uint8 and labels.shape == (480, 640), "classify: uint8 (480, 640)")
check(np.array_equal(labels, png_grey8(inputs / "cli" / "person.labels.png")),
      "classify() == `poseforest infer --labels` (person.labels.png)")
check(labels.tobytes() == (inputs / "person.labels").read_bytes(), "classify() == the runtime's labels")
probs = forest.distributions(depth)
check(probs.dtype == np.float32 and probs.shape == (480, 640, 31), "distributions: float32 (480, 640, 31)")
npy = (inputs / "cli" / "person.probs.npy").read_bytes()
check(probs.tobytes() == npy[128:], "distributions() == `poseforest infer --distributions` (.npy payload, byte for byte)")
check(np.array_equal(np.load(inputs / "cli" / "person.probs.npy"), probs), "np.load(.npy) == distributions()")
check(np.array_equal(forest.classify(depth, threads=1), labels), "classify(threads=1) == classify()")
from_bytes = poseforest.Forest.from_bytes((inputs / "forest.pff").read_bytes(), "forest.pff")
check(np.array_equal(from_bytes.classify(depth), labels), "Forest.from_bytes(...).classify == Forest(path).classify")

# Joints equal the program's joints.json (it prints positions with 4 decimals, confidence %.5g).
joints = forest.joints(depth)
check(joints.dtype.names == ("joint", "position_m", "pixel", "confidence"), "joints: structured array fields")
cli = json.loads((inputs / "cli" / "person.joints.json").read_text())
flat = [(j, p) for j, entry in enumerate(cli["joints"]) for p in entry["proposals"]]
check(len(flat) == len(joints) and len(joints) > 0, f"joints: {len(joints)} proposals, as the program's joints.json")
for (j, p), mine in zip(flat, joints):
    ok = (mine["joint"] == j and cli["joints"][j]["joint"] == poseforest.JOINT_NAMES[j]
          and all(float(f"{float(v):.4f}") == w for v, w in zip(mine["position_m"], p["position_m"]))
          and all(float(f"{float(v):.1f}") == w for v, w in zip(mine["pixel"], p["pixel"]))
          and float(f"{float(mine['confidence']):.5g}") == p["confidence"])
    if not ok:
        sys.exit(f"FAIL: joint proposal {mine} differs from the program's {poseforest.JOINT_NAMES[j]} {p}")
check(True, "every joint proposal equals the program's joints.json")
fast = forest.joints(depth, method="fast")
check(len(fast) > 0, "joints(method='fast')")


def error_of(fn):
    try:
        fn()
    except Exception as e:  # noqa: BLE001 - the type is checked by the caller
        return e
    return None


# Errors: poseforest.Error with the program's message.
for name in ("corrupt.pff", "missing.pff"):
    e = error_of(lambda: poseforest.Forest(str(inputs / name)))
    run = subprocess.run([program, "infer", "--quiet", "--forest", str(inputs / name), str(inputs / "person.raw")],
                         capture_output=True, text=True)
    check(isinstance(e, poseforest.Error) and isinstance(e, RuntimeError), f"{name}: raises poseforest.Error")
    check(run.returncode == 1 and run.stderr == f"poseforest infer: {e}\n",
          f"{name}: message equals the program's: {e}")
e = error_of(lambda: poseforest.Forest.from_bytes(b"\x89PFF" + bytes(100), "junk"))
check(isinstance(e, poseforest.Error) and str(e).startswith("DataLoss: junk"), f"from_bytes(junk): {e}")
five = poseforest.Forest(str(inputs / "forest5.pff"))
e = error_of(lambda: five.joints(depth))
check(isinstance(e, poseforest.Error) and "31-part taxonomy (this one has 5 parts)" in str(e), f"5-part joints: {e}")
check(isinstance(error_of(lambda: forest.classify(depth.astype(np.float32))), TypeError), "float depth: TypeError")
check(isinstance(error_of(lambda: forest.classify(depth[None])), ValueError), "3-D depth: ValueError")
# A side above 32768 is refused, not cut to the C API's int (40000 would not wrap, 2^32 + 640 would).
check(isinstance(error_of(lambda: forest.classify(np.zeros((1, 40000), dtype=np.uint16))), ValueError),
      "a side above 32768: ValueError")
check(isinstance(error_of(lambda: forest.joints(depth, method="x")), ValueError), "unknown method: ValueError")
check(np.array_equal(forest.classify(np.asfortranarray(depth)), labels), "a Fortran-ordered array gives the same labels")

# The GIL is released while the runtime computes: the main thread keeps running Python code
# during one long call (with the GIL held it could not run until the call returned).
sys.setswitchinterval(0.5)
big = np.tile(depth, (4, 4))  # 1920 x 2560
state = {"inside": False, "done": False, "seconds": 0.0}


# Skeletons: the pre-segmented person is one skeleton whose found joints are proposals of
# forest.joints() (a skeleton joint is its joint's most confident proposal on the person).
stream = poseforest.SkeletonStream(forest, threads=2)
people = stream.process(depth, 0.0)
check(len(people) == 1 and people[0]["id"] == 1 and people[0]["pixels"] == int((depth > 0).sum()),
      f"SkeletonStream: one person of {int((depth > 0).sum())} pixels, id 1")
person = people[0]
check([j["name"] for j in person["joints"]] == list(poseforest.JOINT_NAMES), "skeleton: 16 joints in JOINT_NAMES order")
found = [j for j in person["joints"] if j["found"]]
check(len(found) > 0, f"skeleton: {len(found)} joints found")
check(all(set(j) == {"name", "found", "tracked", "position_m", "pixel", "confidence", "state"} for j in person["joints"]),
      "skeleton: each joint has name, found, tracked, position_m, pixel, confidence, state")
for k, j in enumerate(person["joints"]):
    # The state agrees with tracked; "inferred" only for a joint found and not tracked.
    check(j["state"] in ("tracked", "inferred", "not_tracked"), f"skeleton {j['name']}: state {j['state']!r}")
    check((j["state"] == "tracked") == j["tracked"], f"skeleton {j['name']}: state {j['state']} vs tracked {j['tracked']}")
    check(j["state"] != "inferred" or (j["found"] and not j["tracked"]), f"skeleton {j['name']}: inferred but not found")
    if not j["found"]:
        check(j["position_m"] is None and not j["tracked"] and j["confidence"] == 0 and j["state"] == "not_tracked",
              f"skeleton {j['name']}: not found")
        continue
    mine = [p for p in joints if p["joint"] == k]
    check(any(tuple(float(v) for v in p["position_m"]) == j["position_m"] for p in mine),
          f"skeleton {j['name']}: position is one of its proposals")
    check(0 <= j["confidence"] <= 1, f"skeleton {j['name']}: confidence {j['confidence']:.3f} in 0..1")
again = stream.process(depth, 1 / 30)
check(len(again) == 1 and again[0]["id"] == 1 and again[0]["joints"] == person["joints"],
      "SkeletonStream: the same frame again keeps id 1 and the same joints")
try:
    stream.process(depth.astype(np.int32), 0.1)
    check(False, "SkeletonStream.process(int32) raises TypeError")
except TypeError:
    check(True, "SkeletonStream.process(int32) raises TypeError")


def worker():
    state["inside"] = True
    t = time.perf_counter()
    forest.classify(big, threads=1)
    state["seconds"] = time.perf_counter() - t
    state["done"] = True


during = 0
t = threading.Thread(target=worker)
t.start()
while not state["done"]:
    if state["inside"]:
        during += 1
t.join()
check(during > 1000, f"GIL released: the main thread ran {during} loop iterations during a "
      f"{state['seconds'] * 1000:.0f} ms call")
print(f"python_api_check: {checks} checks passed")
