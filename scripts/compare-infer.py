#!/usr/bin/env python3
"""Compares two folders of `poseforest infer` outputs (scripts/cross-arm64.sh --compare: the
x86-64 and the aarch64 runtime on the same frames and forests).

Every *.labels.png and *.joints.json of A must be in B and be byte-identical; where it is not,
the floating-point tolerance applies: labels agree on >= 99.9 % of the pixels, and each joint
has as many proposals, each within 1 mm of its counterpart in the other folder. Exit status 0
when every pair passes either way; the report says which held for each.

usage: compare-infer.py DIR_A DIR_B
"""
import json
import math
import pathlib
import struct
import sys
import zlib

MIN_LABEL_AGREEMENT = 0.999
MAX_JOINT_DISTANCE_M = 0.001


def read_grey8_png(path):
    """(width, height, rows of bytes) of an 8-bit greyscale PNG (what --labels writes)."""
    data = path.read_bytes()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError(f"{path}: not a PNG")
    pos, idat, width = 8, b"", None
    while pos < len(data):
        (length,) = struct.unpack(">I", data[pos : pos + 4])
        kind, body = data[pos + 4 : pos + 8], data[pos + 8 : pos + 8 + length]
        pos += 12 + length
        if kind == b"IHDR":
            width, height, depth, colour = struct.unpack(">IIBB", body[:10])
            if (depth, colour) != (8, 0):
                raise ValueError(f"{path}: not 8-bit greyscale")
        elif kind == b"IDAT":
            idat += body
    raw = zlib.decompress(idat)
    rows, prev = [], bytearray(width)
    for y in range(height):
        f, line = raw[y * (width + 1)], bytearray(raw[y * (width + 1) + 1 : (y + 1) * (width + 1)])
        for x in range(width):
            a = line[x - 1] if x else 0
            b = prev[x]
            c = prev[x - 1] if x else 0
            if f == 1:
                line[x] = (line[x] + a) & 255
            elif f == 2:
                line[x] = (line[x] + b) & 255
            elif f == 3:
                line[x] = (line[x] + (a + b) // 2) & 255
            elif f == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[x] = (line[x] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        rows.append(line)
        prev = line
    return width, height, rows


def compare_labels(a, b):
    wa, ha, ra = read_grey8_png(a)
    wb, hb, rb = read_grey8_png(b)
    if (wa, ha) != (wb, hb):
        return False, f"sizes differ: {wa}x{ha} and {wb}x{hb}"
    same = sum(x == y for la, lb in zip(ra, rb) for x, y in zip(la, lb))
    fg = sum(x != 255 or y != 255 for la, lb in zip(ra, rb) for x, y in zip(la, lb))
    differ = wa * ha - same
    agreement = 1 - differ / max(fg, 1)  # of the foreground pixels (255 = background)
    return agreement >= MIN_LABEL_AGREEMENT, f"{differ} of {fg} foreground pixels differ ({100 * agreement:.3f} % agree)"


def compare_joints(a, b):
    ja, jb = json.loads(a.read_text()), json.loads(b.read_text())
    worst, problems = 0.0, []
    for qa, qb in zip(ja["joints"], jb["joints"]):
        pa, pb = qa["proposals"], qb["proposals"]
        if len(pa) != len(pb):
            problems.append(f"{qa['joint']}: {len(pa)} and {len(pb)} proposals")
            continue
        for p in pa:  # the nearest counterpart: near-equal confidences may swap the order
            d = min(math.dist(p["position_m"], q["position_m"]) for q in pb) if pb else 0.0
            worst = max(worst, d)
    ok = not problems and worst <= MAX_JOINT_DISTANCE_M
    return ok, f"largest joint distance {1000 * worst:.3f} mm" + "".join(f"; {p}" for p in problems)


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    da, db = pathlib.Path(sys.argv[1]), pathlib.Path(sys.argv[2])
    files = sorted(p.relative_to(da) for p in da.rglob("*") if p.name.endswith((".labels.png", ".joints.json")))
    if not files:
        sys.exit(f"compare-infer: no outputs in {da}")
    failed = identical = 0
    for rel in files:
        a, b = da / rel, db / rel
        if not b.exists():
            print(f"FAIL {rel}: missing in {db}")
            failed += 1
            continue
        if a.read_bytes() == b.read_bytes():
            print(f"ok   {rel}: byte-identical ({a.stat().st_size} bytes)")
            identical += 1
            continue
        ok, how = (compare_labels if rel.name.endswith(".png") else compare_joints)(a, b)
        verdict = "within the tolerance" if ok else "OUTSIDE the tolerance"
        print(f"{'ok  ' if ok else 'FAIL'} {rel}: not byte-identical, {verdict}: {how}")
        failed += not ok
    print(f"compare-infer: {len(files)} outputs, {identical} byte-identical, "
          f"{len(files) - identical - failed} within tolerance, {failed} failed")
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
