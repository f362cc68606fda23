#!/usr/bin/env python3
"""How far a simulated capture's workspace is from the simulator's truth in
the head frame: the aligned cameras (cameras_head.json), per camera and the
rotation that takes the estimated head frame to the true one; the tracked
face (the cameras with track's head motion) in one camera; and the landmark
detector's points against the simulator's landmarks, per camera.

    scripts/head_frame_error.py WORKSPACE SIMULATION [--camera cam0]

SIMULATION is the folder `headforge simulate` wrote (its ground_truth.json).
Plain Python, no packages."""
import argparse
import json
import math
import os


def matmul(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(len(b))) for j in range(len(b[0]))] for i in range(len(a))]


def transpose(a):
    return [list(r) for r in zip(*a)]


def rotation(m):
    return [r[:3] for r in m[:3]]


def angle_deg(r):
    return math.degrees(math.acos(max(-1.0, min(1.0, (r[0][0] + r[1][1] + r[2][2] - 1) / 2))))


def rotation_vector_deg(r):
    a = angle_deg(r)
    axis = [r[2][1] - r[1][2], r[0][2] - r[2][0], r[1][0] - r[0][1]]
    n = math.sqrt(sum(x * x for x in axis)) or 1.0
    return [a * x / n for x in axis]


def centre(m):
    rt = transpose(rotation(m))
    return [-sum(rt[i][k] * m[k][3] for k in range(3)) for i in range(3)]


def median(x):
    x = sorted(x)
    return x[len(x) // 2] if x else float("nan")


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("workspace")
    parser.add_argument("simulation")
    parser.add_argument("--camera", default="cam0", help="the camera the tracked face is scored in")
    args = parser.parse_args()
    load = lambda *p: json.load(open(os.path.join(*p)))
    truth = load(args.simulation, "ground_truth.json")
    cameras = load(args.workspace, "cameras_head.json")
    capture = load(args.workspace, "capture.json")
    source = {(c["name"], f["index"]): f["source_frame"] for c in capture["cameras"] for f in c["frames"]}
    # The crop of the source into frames: u = (u_src + 0.5 - x0) * scale - 0.5.
    crops = {c["name"]: c.get("crop", {"x0": 0.0, "y0": 0.0, "scale": 1.0}) for c in capture["cameras"]}

    def true_cam_from_head(camera, frame):
        t = truth["frames"][source[(camera, frame)]]
        return matmul(t["views"][camera]["cam_from_world"], t["world_from_head"])

    per_camera, vectors = {}, []
    for v in cameras["views"]:
        if not v.get("registered"):
            continue
        est, tru = v["cam_from_world"], true_cam_from_head(v["camera"], v["frame"])
        r = matmul(transpose(rotation(est)), rotation(tru))
        per_camera.setdefault(v["camera"], []).append((angle_deg(r), 1000 * math.dist(centre(est), centre(tru))))
        vectors.append(rotation_vector_deg(r))
    if not vectors:
        raise SystemExit("no registered view in cameras_head.json")
    rows = [e for c in per_camera.values() for e in c]
    print("aligned cameras: %d views, rotation median / max %.2f / %.2f deg, centre median / max %.0f / %.0f mm"
          % (len(rows), median([e[0] for e in rows]), max(e[0] for e in rows),
             median([e[1] for e in rows]), max(e[1] for e in rows)))
    print("head frame's error (rotation vector, head axes x, y, z; median over views): %.2f, %.2f, %.2f deg"
          % tuple(median([v[i] for v in vectors]) for i in range(3)))
    for name in sorted(per_camera, key=lambda s: (len(s), s)):
        e = per_camera[name]
        print("  %s: %.1f deg, %.0f mm" % (name, median([x[0] for x in e]), median([x[1] for x in e])))

    tracking_path = os.path.join(args.workspace, "tracking.json")
    if os.path.exists(tracking_path):
        frames = json.load(open(tracking_path))["frames"]
        with_motion, without = [], []
        for v in cameras["views"]:
            if not v.get("registered") or v["camera"] != args.camera or v["frame"] >= len(frames):
                continue
            tru = rotation(true_cam_from_head(v["camera"], v["frame"]))
            face = matmul(v["cam_from_world"], frames[v["frame"]]["head_motion"])
            with_motion.append(angle_deg(matmul(transpose(rotation(face)), tru)))
            without.append(angle_deg(matmul(transpose(rotation(v["cam_from_world"])), tru)))
        if with_motion:
            print("tracked face in %s: rotation median / max %.2f / %.2f deg (the aligned camera alone: %.2f)"
                  % (args.camera, median(with_motion), max(with_motion), median(without)))

    landmarks_path = os.path.join(args.workspace, "landmarks.json")
    if os.path.exists(landmarks_path):
        print("detected landmarks against the simulator's (median px per view, then over views):")
        for name, entries in sorted(json.load(open(landmarks_path))["cameras"].items(), key=lambda i: (len(i[0]), i[0])):
            errors = []
            for e in entries:
                if not e.get("found") or "points" not in e:
                    continue
                crop = crops[name]
                true_points = [((u + 0.5 - crop["x0"]) * crop["scale"] - 0.5, (v + 0.5 - crop["y0"]) * crop["scale"] - 0.5)
                               for u, v in truth["frames"][source[(name, e["index"])]]["views"][name]["landmarks"]]
                errors.append(median([math.dist(p, q) for p, q in zip(e["points"], true_points)]))
            if errors:
                print("  %s: %d views, %.1f px" % (name, len(errors), median(errors)))


if __name__ == "__main__":
    main()
