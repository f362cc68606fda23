#!/usr/bin/env python3
"""The masks a training trains on against a simulation's own masks.

  scripts/mask_iou.py PACK SIM [train|test]

PACK is a training pack (`headforge pack --workspace W --out PACK`, with the
train options whose masks you want: --mask ingest|mesh|hull|auto); SIM the
folder `headforge simulate` wrote for the scene W was ingested from. Each of
the pack's views (the training views by default) is compared with the
simulator's mask of the same camera and instant, resized to the pack's size
by ffmpeg (area), both taken at 128 of 255: prints the mean and the worst
intersection over union. Standard library and ffmpeg only.
"""
import json
import struct
import subprocess
import sys


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    pack, sim = sys.argv[1], sys.argv[2]
    split = sys.argv[3] if len(sys.argv) > 3 else "train"
    truth = json.load(open(sim + "/ground_truth.json"))
    fps = float(truth["fps"])
    raw = open(pack, "rb").read()
    size = struct.unpack("<Q", raw[:8])[0]
    header = json.loads(raw[8:8 + size])
    base = 8 + size
    views = json.loads(header["__metadata__"]["headforge_pack"])["views"]
    ious = []
    for k, view in enumerate(views):
        if view["split"] != split:
            continue
        tensor = header["view.%d.mask" % k]
        begin, end = tensor["data_offsets"]
        height, width = tensor["shape"][1], tensor["shape"][2]
        mask = raw[base + begin:base + end]
        png = "%s/masks/%s/%06d.png" % (sim, view["camera"], round(view["time_s"] * fps))
        other = subprocess.run(["ffmpeg", "-loglevel", "error", "-i", png, "-vf",
                                "scale=%d:%d:flags=area" % (width, height), "-pix_fmt", "gray",
                                "-f", "rawvideo", "-"], capture_output=True, check=True).stdout
        both = either = 0
        for a, b in zip(mask, other):
            both += a >= 128 and b >= 128
            either += a >= 128 or b >= 128
        ious.append(both / max(either, 1))
    if not ious:
        sys.exit("mask_iou: the pack has no %s views" % split)
    print("%s views: %d, mean IoU %.4f, worst %.4f" % (split, len(ious), sum(ious) / len(ious), min(ious)))


if __name__ == "__main__":
    main()
