#!/usr/bin/env bash
# A multi-view dome end to end: simulates scenes/dome_360.toml (20 fixed
# cameras all round a talking head, the back included, as image folders, with
# the head masks a studio's matting would give), runs `headforge run` on the
# 20 folders with those masks and the rig's calibration (ingest keeps the
# cameras that never see the face, calibrate reads the rig file, align,
# track, train picks the gaussian-style avatar
# and holds three cameras out whole: the subject's left side, the back and
# the right side), then scores the held-out cameras' views against the
# simulator's frames and masks (`render --truth`).
#   scripts/dome.sh [out] [run options]   (default /tmp/headforge_dome; resumes)
# DOME_SCENE picks the scene file in scenes/ (dome_360, or dome_360_lit: the
# same dome under one light; or any rig scene, e.g. rig_8cam), DOME_HOLDOUT
# the cameras held out whole (default cam3,cam6,cam9), DOME_CAMERAS where the
# cameras come from: rig (default: the rig file) or colmap (COLMAP on three
# synchronised instants, --rig-instants 3, as without a studio calibration).
# Options after the folder go to `headforge run`; without any, --fps 12.5
# (25 instants of the 2-second scene) --multiview-mesh-weight 0.4 (track
# fits the face mesh beside the 68 points: the unlit dome's turned views
# defeat the 68-point predictor; docs/tracking.md).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="${HEADFORGE_BUILD_DIR:-$root/build}"
bin="$build/pipelines/headforge"
out="${1:-/tmp/headforge_dome}"
shift || true
[ $# -gt 0 ] || set -- --fps 12.5 --multiview-mesh-weight 0.4
mkdir -p "$out"
scene="${DOME_SCENE:-dome_360}"
[ -f "$root/scenes/$scene.toml" ] || { echo "dome.sh: no scene scenes/$scene.toml" >&2; exit 2; }
[ -f "$out/sim/ground_truth.json" ] || "$bin" simulate --scene "$root/scenes/$scene.toml" --out "$out/sim"
# The rig's calibration, as a studio has it (a rig file: docs/calibration.md),
# from the simulator's cameras. COLMAP on one synchronised instant of the
# dome places some back cameras in front of the face (docs/benchmarks/capture_360.md).
if [ ! -f "$out/rig.json" ]; then
  python3 - "$out/sim/ground_truth.json" "$out/rig.json" <<'PY'
import json, sys
truth = json.load(open(sys.argv[1]))
views = truth["frames"][0]["views"]
# The simulator's world is in metres, as a studio's calibration is.
rig = {"metres_per_unit": 1.0,
       "cameras": [dict({k: c[k] for k in ("name", "width", "height", "fx", "fy", "cx", "cy", "k1", "k2")},
                        cam_from_world=views[c["name"]]["cam_from_world"]) for c in truth["cameras"]]}
json.dump(rig, open(sys.argv[2], "w"), indent=1)
PY
fi
count=$(python3 -c 'import json, sys; print(len(json.load(open(sys.argv[1]))["cameras"]))' "$out/sim/ground_truth.json")
cameras=()
for c in $(seq 0 $((count - 1))); do cameras+=("$out/sim/cam$c"); done
start=$(date +%s)
case "${DOME_CAMERAS:-rig}" in
  rig) calibration=(--mode rig --rig "$out/rig.json") ;;
  colmap) calibration=(--rig-instants 3) ;;
  *) echo "dome.sh: DOME_CAMERAS is rig or colmap, not ${DOME_CAMERAS}" >&2; exit 2 ;;
esac
"$bin" run --video "${cameras[@]}" --mask-folder "$out/sim/masks" "${calibration[@]}" \
  --holdout-cameras "${DOME_HOLDOUT:-cam3,cam6,cam9}" --workspace "$out/ws" "$@"
echo "dome: run took $(( $(date +%s) - start )) s"
"$bin" status "$out/ws"
"$bin" render --workspace "$out/ws" --truth "$out/sim" --out "$out/novel_views"
echo "dome: the orbit video is $out/ws/export/videos/orbit.mp4, the report $out/ws/export/report.html;"
echo "      held-out cameras against the truth in $out/novel_views"
