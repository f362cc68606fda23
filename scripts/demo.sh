#!/usr/bin/env bash
# The demo: installs what is missing, builds, and runs `headforge run` on a real
# GRID talking-head clip into demo_workspace/ (resumes if run again).
#   scripts/demo.sh [video] [workspace]
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="${HEADFORGE_BUILD_DIR:-$root/build}"
video="${1:-$root/../shared/data/video/grid/bbaf2n.mpg}"
workspace="${2:-$root/demo_workspace}"
"$root/scripts/install_deps.sh"
"$root/scripts/build.sh"
"$build/pipelines/headforge" run --video "$video" --workspace "$workspace"
"$build/pipelines/headforge" status "$workspace"
echo "demo: frames, landmarks, cameras, tracking.json, overlay_cam0.mp4 (the fitted face) and the avatar"
echo "      (models/gaussian_style/: eval.json scores the held-out frames) are in $workspace;"
echo "      what other tools open is in $workspace/export: report.html (the run in one page),"
echo "      viewer/index.html (both avatars in a browser, offline),"
echo "      avatar_mesh.glb (glTF: blendshapes, the tracked animation, a baked texture),"
echo "      gaussians.ply and gaussians.glb (KHR_gaussian_splatting), weights/ (safetensors),"
echo "      videos/self_reenactment.mp4 (held-out frames: render | frame | error) and videos/orbit.mp4"
