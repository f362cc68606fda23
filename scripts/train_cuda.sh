#!/usr/bin/env bash
# headforge-train on an NVIDIA GPU, for a machine that has PyTorch (whose
# package holds LibTorch with CUDA) but not the rest of HeadForge's stack:
# configures build-cuda/ with HEADFORGE_SPLAT_ONLY (LibTorch, Eigen and
# nlohmann-json are all it needs), builds headforge-train, and with arguments
# runs it on a training pack written by `headforge pack` on the GPU.
#   scripts/train_cuda.sh                          build only
#   scripts/train_cuda.sh PACK --out DIR [headforge-train options]
# LibTorch is found from python3's torch unless Torch_DIR is set; Eigen and
# nlohmann-json from CMAKE_PREFIX_PATH (or the system). HEADFORGE_CUDA_TESTS=ON
# builds the rasterizer's GPU tests too, avatar_cuda_test (then
# GoogleTest is needed); HEADFORGE_CUDA_BENCHMARKS=ON the rasterizer's
# benchmark, headforge_splat_bench (then Google Benchmark is needed).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="${HEADFORGE_CUDA_BUILD_DIR:-$root/build-cuda}"
prefix="${CMAKE_PREFIX_PATH:-}"
if [ -z "${Torch_DIR:-}" ]; then
  torch_prefix="$(python3 -c 'import torch; print(torch.utils.cmake_prefix_path)')" || {
    echo "train_cuda.sh: python3 cannot import torch; set Torch_DIR to a CUDA LibTorch's share/cmake/Torch" >&2
    exit 1
  }
  prefix="$torch_prefix${prefix:+;$prefix}"
fi
mkdir -p "$build"
generator=()
command -v ninja >/dev/null && generator=(-G Ninja)
tests="${HEADFORGE_CUDA_TESTS:-OFF}"
benchmarks="${HEADFORGE_CUDA_BENCHMARKS:-OFF}"
cmake -S "$root" -B "$build" "${generator[@]}" -DCMAKE_BUILD_TYPE=Release -DHEADFORGE_SPLAT_ONLY=ON \
  -DHEADFORGE_UNITY_BUILD=OFF -DHEADFORGE_BUILD_TESTS="$tests" -DHEADFORGE_BUILD_BENCHMARKS="$benchmarks" \
  -DCMAKE_PREFIX_PATH="$prefix" >"$build/configure.log" 2>&1 || {
  cat "$build/configure.log" >&2
  exit 1
}
if ! grep -q '^HEADFORGE_CUDA_ARCHITECTURES' "$build/CMakeCache.txt"; then
  echo "train_cuda.sh: the LibTorch found has no CUDA (or no CUDA compiler was found); see $build/configure.log" >&2
  exit 1
fi
targets=(headforge_train)
[ "$tests" = ON ] && targets+=(avatar_cuda_test)
[ "$benchmarks" = ON ] && targets+=(headforge_splat_bench)
cmake --build "$build" --parallel "$(nproc)" --target "${targets[@]}"
if [ $# -gt 0 ]; then
  exec "$build/avatar/headforge-train" --device cuda "$@"
fi
