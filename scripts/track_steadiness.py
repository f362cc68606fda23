#!/usr/bin/env python3
"""How steady a fixed-camera workspace's 68 points and head poses are.

For each tracked workspace given (one camera, head-pose cameras), prints:
track's median landmark residual (tracking.json), the calibrated focal
length (cameras.json), the median over points and frames of the 68 points'
second difference |p[f-1] - 2 p[f] + p[f+1]| (pixels of the ingested
frames: how much a point jumps beyond a steady motion), and the median turn
and change of distance of the head between consecutive frames.

    python3 scripts/track_steadiness.py WORKSPACE [WORKSPACE ...]
"""
import json
import math
import sys


def angle_deg(r):
    c = (r[0][0] + r[1][1] + r[2][2] - 1) / 2
    return math.degrees(math.acos(max(-1.0, min(1.0, c))))


def relative(a, b):
    # a b^T for 3x3 rotations given as lists of rows.
    return [[sum(a[i][k] * b[j][k] for k in range(3)) for j in range(3)] for i in range(3)]


def median(values):
    s = sorted(values)
    return s[len(s) // 2] if s else float("nan")


def report(ws):
    with open(ws + "/tracking.json") as f:
        tracking = json.load(f)
    with open(ws + "/cameras.json") as f:
        cameras = json.load(f)
    with open(ws + "/landmarks.json") as f:
        landmarks = json.load(f)["cameras"]
    if len(landmarks) != 1 or cameras.get("mode") != "head-pose":
        sys.exit(ws + ": one fixed camera (head-pose cameras) is what this script reads")
    frames = next(iter(landmarks.values()))
    jumps = []
    for a, b, c in zip(frames, frames[1:], frames[2:]):
        if not (a.get("found") and b.get("found") and c.get("found")):
            continue
        for i in range(68):
            jumps.append(math.hypot(a["points"][i][0] - 2 * b["points"][i][0] + c["points"][i][0],
                                    a["points"][i][1] - 2 * b["points"][i][1] + c["points"][i][1]))
    turns, moves = [], []
    views = cameras["views"]
    for a, b in zip(views, views[1:]):
        ra = [row[:3] for row in a["cam_from_world"][:3]]
        rb = [row[:3] for row in b["cam_from_world"][:3]]
        turns.append(angle_deg(relative(ra, rb)))
        moves.append(abs(a["cam_from_world"][2][3] - b["cam_from_world"][2][3]) * 1000)
    print("%s: residual %.3f px, focal %.1f px, 68 points' second difference %.3f px, "
          "turn between frames %.3f deg, distance change %.2f mm"
          % (ws, tracking["median_residual_px"], cameras["cameras"][0]["fx"], median(jumps), median(turns),
             median(moves)))


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    for workspace in sys.argv[1:]:
        report(workspace)
