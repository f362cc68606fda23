#!/usr/bin/env bash
# The 360-degree path end to end on a simulated walk-around video: simulates
# scenes/walkaround_360.toml (one camera walked once round a still head,
# written as an H.264 video), runs `headforge run` on the video (ingest keeps
# whole frames, COLMAP, align, track, train picks the gaussian-style avatar
# on masks made to agree across the views (--mask auto: hull), export writes
# the 360-degree orbit video and the viewer), then scores the held-out
# frames against the simulator's own clean frames and masks from the true
# cameras (`render --truth`).
#   scripts/walkaround.sh [out] [run options]   (default /tmp/headforge_walkaround; resumes)
# Options after the folder go to `headforge run`; without any, every frame
# of the video (150, 2.4 degrees apart: COLMAP's sequential mapping finds too
# little parallax between neighbours, and calibrate maps one in three and
# registers the rest; about 5 minutes of COLMAP here). `--fps 8.333` takes 50
# frames, 7.2 degrees apart, which COLMAP maps directly in about 80 s: faster,
# with a third of the views to train on (held out about 1 dB lower).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="${HEADFORGE_BUILD_DIR:-$root/build}"
bin="$build/pipelines/headforge"
out="${1:-/tmp/headforge_walkaround}"
shift || true
mkdir -p "$out"
scene="$root/scenes/walkaround_360.toml"
[ -f "$out/video/cam0.mp4" ] || "$bin" simulate --scene "$scene" --out "$out/video"
# The truth: the same scene as PNG frames, without the video's compression.
if [ ! -f "$out/truth/ground_truth.json" ]; then
  sed 's/^effects = .*/effects = []/' "$scene" > "$out/truth_scene.toml"
  "$bin" simulate --scene "$out/truth_scene.toml" --out "$out/truth"
fi
start=$(date +%s)
"$bin" run --video "$out/video/cam0.mp4" --workspace "$out/ws" "$@"
echo "walkaround: run took $(( $(date +%s) - start )) s"
"$bin" status "$out/ws"
"$bin" render --workspace "$out/ws" --truth "$out/truth" --out "$out/novel_views"
echo "walkaround: the orbit video is $out/ws/export/videos/orbit.mp4, the viewer $out/ws/export/viewer/index.html,"
echo "            the report $out/ws/export/report.html; held-out views against the truth in $out/novel_views"
