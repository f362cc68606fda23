#!/usr/bin/env bash
# Renders one frame of each bundled scene into docs/images/ (the pictures in
# docs/simulator.md). Needs a build (scripts/build.sh).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
headforge="${HEADFORGE_BUILD_DIR:-$root/build}/pipelines/headforge"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
mkdir -p "$root/docs/images"
for scene in talking_static orbit_360 rig_8cam; do
  "$headforge" simulate --scene "$root/scenes/$scene.toml" --out "$tmp/$scene" --frames 12 --log-level warning
done
cp "$tmp/talking_static/cam0/000010.png" "$root/docs/images/talking_static.png"
cp "$tmp/orbit_360/cam0/000005.png" "$root/docs/images/orbit_360.png"
cp "$tmp/rig_8cam/cam2/000011.png" "$root/docs/images/rig_8cam.png"
echo "scene_pictures: wrote docs/images/{talking_static,orbit_360,rig_8cam}.png"
