// Speed and peak memory of the Gaussian rasterizer on a fixed scene: a camera
// at the origin looking down +z with a 60 degree field of view; means uniform
// in [-1.5, 1.5] x [-1.5, 1.5] x [2, 4]; scales log-uniform in [0.005, 0.02];
// uniformly random rotations; opacity uniform in [0.1, 0.9]; features uniform
// in [0, 1]; black background; seed 0. Arguments: N, image side, channels.
//   build/bench/headforge_splat_bench                       (all sizes)
//   build/bench/headforge_splat_bench --benchmark_filter='/100000/512/'
// "peak_MiB" is the growth of the process's peak resident memory over one
// iteration (VmHWM, reset through /proc/self/clear_refs before it).
#include <benchmark/benchmark.h>
#include <torch/torch.h>

#include <cmath>
#include <fstream>
#include <string>

#include "avatar/splat_ops.h"
#include "avatar/torch_runtime.h"
#include "core/parallel.h"

namespace headforge {
namespace {

struct BenchScene {
  torch::Tensor means, quats, log_scales, opacities, features;
  SplatCamera camera;
};

BenchScene MakeScene(int64_t n, int side, int64_t channels) {
  auto gen = at::detail::createCPUGenerator(0);
  const auto opts = torch::TensorOptions().dtype(torch::kFloat32);
  BenchScene s;
  const auto xy = torch::rand({n, 2}, gen, opts) * 3.0 - 1.5;
  const auto z = torch::rand({n, 1}, gen, opts) * 2.0 + 2.0;
  s.means = torch::cat({xy, z}, 1);
  const auto q = torch::randn({n, 4}, gen, opts);
  s.quats = q / q.norm(2, 1, true);
  s.log_scales = torch::rand({n, 3}, gen, opts) * (std::log(0.02) - std::log(0.005)) + std::log(0.005);
  s.opacities = torch::rand({n}, gen, opts) * 0.8 + 0.1;
  s.features = torch::rand({n, channels}, gen, opts);
  s.camera.width = s.camera.height = side;
  s.camera.fx = s.camera.fy = 0.5 * side / std::tan(30.0 * M_PI / 180.0);
  s.camera.cx = s.camera.cy = 0.5 * side - 0.5;
  return s;
}

// Peak resident memory in KiB, and its reset to the current value.
int64_t PeakRssKiB() {
  std::ifstream status("/proc/self/status");
  std::string key;
  while (status >> key) {
    if (key == "VmHWM:") {
      int64_t kib = 0;
      status >> kib;
      return kib;
    }
    status.ignore(1 << 10, '\n');
  }
  return 0;
}
int64_t CurrentRssKiB() {
  std::ifstream status("/proc/self/status");
  std::string key;
  while (status >> key) {
    if (key == "VmRSS:") {
      int64_t kib = 0;
      status >> kib;
      return kib;
    }
    status.ignore(1 << 10, '\n');
  }
  return 0;
}
void ResetPeakRss() { std::ofstream("/proc/self/clear_refs") << "5"; }

void SetCounters(benchmark::State& state, const BenchScene& s, double peak_mib) {
  state.counters["peak_MiB"] = peak_mib;
  state.SetLabel(std::to_string(s.means.size(0)) + " Gaussians, " + std::to_string(s.camera.width) +
                 "^2, C=" + std::to_string(s.features.size(1)));
}

struct Leaves {
  torch::Tensor means, quats, log_scales, opacities, features;
  explicit Leaves(const BenchScene& s)
      : means(s.means.clone().requires_grad_(true)),
        quats(s.quats.clone().requires_grad_(true)),
        log_scales(s.log_scales.clone().requires_grad_(true)),
        opacities(s.opacities.clone().requires_grad_(true)),
        features(s.features.clone().requires_grad_(true)) {}
  SplatRenderResult Render(const SplatCamera& camera) const {
    return RenderGaussians(means, quats, log_scales, opacities, features, {}, camera);
  }
};

// Project + intersect + rasterize, recording the graph as training does.
void BM_SplatForward(benchmark::State& state) {
  const BenchScene s = MakeScene(state.range(0), int(state.range(1)), state.range(2));
  const Leaves leaves(s);
  double peak = 0;
  for (auto _ : state) {
    ResetPeakRss();
    const int64_t before = CurrentRssKiB();
    auto out = leaves.Render(s.camera);
    benchmark::DoNotOptimize(out.image.data_ptr());
    peak = std::max(peak, (PeakRssKiB() - before) / 1024.0);
  }
  SetCounters(state, s, peak);
}

// The backward of one render (all inputs), given d loss / d image.
void BM_SplatBackward(benchmark::State& state) {
  const BenchScene s = MakeScene(state.range(0), int(state.range(1)), state.range(2));
  const Leaves leaves(s);
  auto gen = at::detail::createCPUGenerator(1);
  const auto v_image = torch::randn({s.features.size(1), s.camera.height, s.camera.width}, gen);
  double peak = 0;
  for (auto _ : state) {
    state.PauseTiming();
    auto out = leaves.Render(s.camera);
    ResetPeakRss();
    const int64_t before = CurrentRssKiB();
    state.ResumeTiming();
    out.image.backward(v_image);
    peak = std::max(peak, (PeakRssKiB() - before) / 1024.0);
    state.PauseTiming();
    for (auto* t : {&leaves.means, &leaves.quats, &leaves.log_scales, &leaves.opacities,
                    &leaves.features}) {
      t->mutable_grad().reset();
    }
    state.ResumeTiming();
  }
  SetCounters(state, s, peak);
}

// Forward and backward together: one training step's rendering.
void BM_SplatForwardBackward(benchmark::State& state) {
  const BenchScene s = MakeScene(state.range(0), int(state.range(1)), state.range(2));
  const Leaves leaves(s);
  auto gen = at::detail::createCPUGenerator(1);
  const auto v_image = torch::randn({s.features.size(1), s.camera.height, s.camera.width}, gen);
  double peak = 0;
  for (auto _ : state) {
    ResetPeakRss();
    const int64_t before = CurrentRssKiB();
    auto out = leaves.Render(s.camera);
    out.image.backward(v_image);
    peak = std::max(peak, (PeakRssKiB() - before) / 1024.0);
    for (auto* t : {&leaves.means, &leaves.quats, &leaves.log_scales, &leaves.opacities,
                    &leaves.features}) {
      t->mutable_grad().reset();
    }
  }
  SetCounters(state, s, peak);
}

void Sizes(benchmark::internal::Benchmark* b) {
  for (int64_t channels : {3, 32}) {
    for (int64_t n : {10000, 100000, 500000}) {
      for (int64_t side : {256, 512, 1024}) b->Args({n, side, channels});
    }
  }
  b->ArgNames({"N", "side", "C"})->Unit(benchmark::kMillisecond)->UseRealTime();
}

BENCHMARK(BM_SplatForward)->Apply(Sizes);
BENCHMARK(BM_SplatBackward)->Apply(Sizes);
BENCHMARK(BM_SplatForwardBackward)->Apply(Sizes);

}  // namespace
}  // namespace headforge

int main(int argc, char** argv) {
  headforge::ConfigureTorchThreads(headforge::HardwareThreads());
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::AddCustomContext("torch", headforge::TorchDescription());
  benchmark::AddCustomContext("threads", std::to_string(headforge::HardwareThreads()));
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
