#!/usr/bin/env python3
"""Where ingest's 68 points sit against the simulator's landmark projections.

  scripts/landmark_offsets.py WS SIM [camera]

WS is a workspace ingested from a simulated capture, SIM the folder
`headforge simulate` wrote for it. Each frame's points are mapped from the
ingested frame back to the source through the crop in capture.json and
compared with the simulator's projections of the face model's landmark
vertices (which are not where a detector's points sit: compare two
workspaces of one subject, not a workspace with zero). Prints, per group
(jaw, brows, nose, eyes, mouth), the median distance and the median
offset in x and y (source pixels, y down). Standard library only.
"""
import json
import sys

GROUPS = [("jaw", 0, 17), ("brows", 17, 27), ("nose", 27, 36), ("eyes", 36, 48), ("mouth", 48, 68)]


def median(values):
    values = sorted(values)
    return values[len(values) // 2] if values else float("nan")


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    ws, sim = sys.argv[1], sys.argv[2]
    camera = sys.argv[3] if len(sys.argv) > 3 else "cam0"
    truth = json.load(open(sim + "/ground_truth.json"))
    crop = next(c for c in json.load(open(ws + "/capture.json"))["cameras"] if c["name"] == camera)["crop"]
    frames = json.load(open(ws + "/landmarks.json"))["cameras"][camera]
    found = {name: {"d": [], "x": [], "y": []} for name, _, _ in GROUPS}
    used = 0
    for frame in frames:
        points = frame.get("points")
        if not points:
            continue
        if isinstance(points[0], (int, float)):
            points = [points[i:i + 2] for i in range(0, len(points), 2)]
        projected = truth["frames"][frame["index"]]["views"][camera]["landmarks"]
        used += 1
        for name, begin, end in GROUPS:
            for p, q in zip(points[begin:end], projected[begin:end]):
                x = (p[0] + 0.5) / crop["scale"] - 0.5 + crop["x0"] - q[0]
                y = (p[1] + 0.5) / crop["scale"] - 0.5 + crop["y0"] - q[1]
                found[name]["d"].append((x * x + y * y) ** 0.5)
                found[name]["x"].append(x)
                found[name]["y"].append(y)
    print("%d frames with points; source pixels, median over the frames" % used)
    print("| group | distance | x offset | y offset |\n|---|---|---|---|")
    for name, _, _ in GROUPS:
        g = found[name]
        print("| %s | %.2f | %+.2f | %+.2f |" % (name, median(g["d"]), median(g["x"]), median(g["y"])))


if __name__ == "__main__":
    main()
