#!/usr/bin/env python3
"""Where a held-out render's error lies inside the simulator's head mask.

  scripts/region_error.py STRIPS SIM [--bottom 0.2] [--edge 2]

STRIPS is the folder `headforge render --truth SIM --out STRIPS` wrote (one
strip per held-out view, CAMERA_FRAME.png: the render, the simulator's clean
frame, their difference, each a square of the training size); SIM the folder
`headforge simulate` wrote. Inside each view's simulator mask (resized to the
strip's squares by ffmpeg, area, taken at 128 of 255) the squared error of the
render against the clean frame is split into the mask's lowest --bottom
fraction of rows (a bust's cut, the neck) and the pixels within --edge pixels
of the mask's outline; prints each view's PSNR and shares and the totals, with
the PSNR left when either part is taken out. The PSNR here is of the 8-bit
strips, so it differs a little from render's own figure. Standard library and
ffmpeg only.
"""
import math
import os
import subprocess
import sys


def raw(path, pix_fmt, crop=None, size=None):
    filters = ([crop] if crop else []) + (["scale=%d:%d:flags=area" % size] if size else [])
    command = ["ffmpeg", "-loglevel", "error", "-i", path]
    if filters:
        command += ["-vf", ",".join(filters)]
    return subprocess.run(command + ["-pix_fmt", pix_fmt, "-f", "rawvideo", "-"], capture_output=True,
                          check=True).stdout


def strip_size(path):
    out = subprocess.run(["ffprobe", "-v", "error", "-select_streams", "v:0", "-show_entries",
                          "stream=width,height", "-of", "csv=p=0", path], capture_output=True, check=True,
                         text=True).stdout.strip()
    width, height = (int(x) for x in out.split(","))
    return width, height


def psnr(squared, count):
    return -10 * math.log10(squared / count) if squared > 0 else float("inf")


def main():
    args = sys.argv[1:]
    options = {"--bottom": 0.2, "--edge": 2}
    positional = []
    while args:
        a = args.pop(0)
        if a in options:
            options[a] = type(options[a])(args.pop(0))
        else:
            positional.append(a)
    if len(positional) != 2:
        sys.exit(__doc__)
    strips, sim = positional
    bottom, edge = options["--bottom"], options["--edge"]
    names = sorted(f for f in os.listdir(strips) if f.endswith(".png") and "_" in f)
    if not names:
        sys.exit("no strips (CAMERA_FRAME.png) in " + strips)
    total = [0.0, 0.0, 0.0, 0]  # all, bottom, edge, pixels
    print("view  PSNR  bottom-share  edge-share")
    for name in names:
        camera, frame = name[:-4].rsplit("_", 1)
        width, height = strip_size(os.path.join(strips, name))
        side = height
        if width < 2 * side:
            sys.exit(name + ": not a strip of squares")
        render = raw(os.path.join(strips, name), "rgb24", crop="crop=%d:%d:0:0" % (side, side))
        truth = raw(os.path.join(strips, name), "rgb24", crop="crop=%d:%d:%d:0" % (side, side, side))
        mask = raw(os.path.join(sim, "masks", camera, "%06d.png" % int(frame)), "gray", size=(side, side))
        inside = [m >= 128 for m in mask]
        rows = [y for y in range(side) if any(inside[y * side:(y + 1) * side])]
        if not rows:
            continue
        cut = rows[-1] - bottom * (rows[-1] - rows[0])
        sums = [0.0, 0.0, 0.0, 0]
        for y in range(side):
            for x in range(side):
                i = y * side + x
                if not inside[i]:
                    continue
                e = sum(((render[3 * i + c] - truth[3 * i + c]) / 255.0) ** 2 for c in range(3)) / 3
                sums[0] += e
                sums[3] += 1
                if y > cut:
                    sums[1] += e
                near = any(not (0 <= y + dy < side and 0 <= x + dx < side) or not inside[(y + dy) * side + x + dx]
                           for dy in range(-edge, edge + 1) for dx in range(-edge, edge + 1))
                if near:
                    sums[2] += e
        for k in range(4):
            total[k] += sums[k]
        print("%s  %.2f dB  %3.0f %%  %3.0f %%" % (name[:-4], psnr(sums[0], sums[3]), 100 * sums[1] / max(sums[0], 1e-12),
                                                  100 * sums[2] / max(sums[0], 1e-12)))
    print("all %d views: %.2f dB; lowest %.0f %% of the mask's rows %.0f %% of the squared error (%.2f dB without "
          "them), within %d px of its outline %.0f %% (%.2f dB without)" %
          (len(names), psnr(total[0], total[3]), 100 * bottom, 100 * total[1] / total[0],
           psnr(total[0] - total[1], total[3]), edge, 100 * total[2] / total[0], psnr(total[0] - total[2], total[3])))


if __name__ == "__main__":
    main()
