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

if [ ${#missing[@]} -eq 0 ]; then
  echo "install_deps: all ${#PACKAGES[@]} packages present"
  install_node_tools
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
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
install_node_tools
echo "install_deps: done"
