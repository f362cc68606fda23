#!/usr/bin/env bash
# The Gaussian rasterizer alone, with its CUDA kernels, on a machine with an
# NVIDIA GPU and PyTorch (whose package holds LibTorch with CUDA) or a CUDA
# LibTorch: configures build-cuda/ with HEADFORGE_SPLAT_ONLY (LibTorch, Eigen,
# nlohmann-json, GoogleTest and Google Benchmark are all it needs), builds,
# runs the tests (avatar_test on the CPU kernels, avatar_cuda_test on the
# GPU), then with "bench" the benchmark on the GPU (README's GPU table).
#   scripts/splat_cuda.sh [bench] [--benchmark_* arguments...]
# LibTorch is found from python3's torch unless Torch_DIR is set; more
# prefixes (GoogleTest, Google Benchmark, Eigen, nlohmann-json) come from
# CMAKE_PREFIX_PATH.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="${HEADFORGE_CUDA_BUILD_DIR:-$root/build-cuda}"
bench=0
if [ "${1:-}" = bench ]; then
  bench=1
  shift
fi
prefix="${CMAKE_PREFIX_PATH:-}"
if [ -z "${Torch_DIR:-}" ]; then
  torch_prefix="$(python3 -c 'import torch; print(torch.utils.cmake_prefix_path)')" || {
    echo "splat_cuda.sh: python3 cannot import torch; set Torch_DIR to a CUDA LibTorch's share/cmake/Torch" >&2
    exit 1
  }
  prefix="$torch_prefix${prefix:+;$prefix}"
fi
generator=()
command -v ninja >/dev/null && generator=(-G Ninja)
cmake -S "$root" -B "$build" "${generator[@]}" -DCMAKE_BUILD_TYPE=Release \
  -DHEADFORGE_SPLAT_ONLY=ON -DHEADFORGE_UNITY_BUILD=OFF -DCMAKE_PREFIX_PATH="$prefix"
if ! grep -q '^HEADFORGE_CUDA_ARCHITECTURES' "$build/CMakeCache.txt"; then
  echo "splat_cuda.sh: the LibTorch found has no CUDA (or no CUDA compiler was found); see the configure output" >&2
  exit 1
fi
cmake --build "$build" --parallel "$(nproc)"
"$build/avatar/avatar_test" --gtest_brief=1
"$build/avatar/avatar_cuda_test" --gtest_brief=1
if [ "$bench" = 1 ]; then
  "$build/bench/headforge_splat_bench" --device=cuda --markdown "$@"
fi
