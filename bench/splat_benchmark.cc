// Speed and peak memory of the Gaussian rasterizer on a fixed scene: a camera
// at the origin looking down +z with a 60 degree field of view; means uniform
// in [-1.5, 1.5] x [-1.5, 1.5] x [2, 4]; scales log-uniform in [0.005, 0.02];
// uniformly random rotations; opacity uniform in [0.1, 0.9]; features uniform
// in [0, 1]; black background; seed 0. Arguments: N, image side, channels.
//   build/bench/headforge_splat_bench                       (all sizes)
//   build/bench/headforge_splat_bench --benchmark_filter='N:100000/side:512/'
//   build/bench/headforge_splat_bench --markdown   (also prints README's table)
//   build/bench/headforge_splat_bench --device=cuda   (the CUDA kernels, in
//                                                       a build with CUDA)
// On the CPU "peak_MiB" is the growth of the process's peak resident memory
// over one iteration (VmHWM, reset through /proc/self/clear_refs before it),
// with blocks over 256 KiB mapped and unmapped directly so freed memory
// leaves. On a GPU it is the growth of LibTorch's peak allocated device
// memory over one iteration. GPU timings wait for the device each iteration.
#include <benchmark/benchmark.h>
#include <torch/torch.h>

#include <malloc.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <regex>
#include <string>
#include <thread>

#ifdef HEADFORGE_WITH_CUDA
#include <c10/cuda/CUDACachingAllocator.h>
#endif

#include "avatar/splat/splat_ops.h"
#include "avatar/torch_runtime.h"

namespace headforge {
namespace {

// Where the benchmarks run (--device).
torch::Device g_device = torch::kCPU;

int HardwareThreads() { return std::max(1, int(std::thread::hardware_concurrency())); }

// Waits for the device's queued work (a no-op on the CPU).
void Sync() {
  if (g_device.is_cuda()) torch::cuda::synchronize();
}

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
  for (auto* t : {&s.means, &s.quats, &s.log_scales, &s.opacities, &s.features}) {
    *t = t->to(g_device);
  }
  return s;
}

// A field of /proc/self/status in KiB ("VmHWM:" the peak resident memory,
// "VmRSS:" the current one).
int64_t StatusKiB(const std::string& field) {
  std::ifstream status("/proc/self/status");
  std::string key;
  while (status >> key) {
    if (key == field) {
      int64_t kib = 0;
      status >> kib;
      return kib;
    }
    status.ignore(1 << 10, '\n');
  }
  return 0;
}
int64_t PeakRssKiB() { return StatusKiB("VmHWM:"); }
int64_t CurrentRssKiB() { return StatusKiB("VmRSS:"); }

#ifdef HEADFORGE_WITH_CUDA
// LibTorch's allocated device memory, all pools together (entry 0,
// StatType::AGGREGATE).
auto Allocated() {
  return c10::cuda::CUDACachingAllocator::getDeviceStats(g_device.index()).allocated_bytes[0];
}
#endif

// The peak memory of one iteration: start before it, read after it.
class PeakMemory {
 public:
  void Start() {
#ifdef HEADFORGE_WITH_CUDA
    if (g_device.is_cuda()) {
      c10::cuda::CUDACachingAllocator::resetPeakStats(g_device.index());
      before_ = Allocated().current;
      return;
    }
#endif
    std::ofstream("/proc/self/clear_refs") << "5";
    before_ = CurrentRssKiB() * 1024;
  }
  double GrowthMiB() const {
#ifdef HEADFORGE_WITH_CUDA
    if (g_device.is_cuda()) return double(Allocated().peak - before_) / (1 << 20);
#endif
    return double(PeakRssKiB() * 1024 - before_) / (1 << 20);
  }

 private:
  int64_t before_ = 0;
};

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
  PeakMemory memory;
  for (auto _ : state) {
    memory.Start();
    auto out = leaves.Render(s.camera);
    benchmark::DoNotOptimize(out.image.data_ptr());
    Sync();
    peak = std::max(peak, memory.GrowthMiB());
  }
  SetCounters(state, s, peak);
}

// The backward of one render (all inputs), given d loss / d image.
void BM_SplatBackward(benchmark::State& state) {
  const BenchScene s = MakeScene(state.range(0), int(state.range(1)), state.range(2));
  const Leaves leaves(s);
  auto gen = at::detail::createCPUGenerator(1);
  const auto v_image =
      torch::randn({s.features.size(1), s.camera.height, s.camera.width}, gen).to(g_device);
  double peak = 0;
  PeakMemory memory;
  for (auto _ : state) {
    state.PauseTiming();
    auto out = leaves.Render(s.camera);
    Sync();
    memory.Start();
    state.ResumeTiming();
    out.image.backward(v_image);
    Sync();
    peak = std::max(peak, memory.GrowthMiB());
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
  const auto v_image =
      torch::randn({s.features.size(1), s.camera.height, s.camera.width}, gen).to(g_device);
  double peak = 0;
  PeakMemory memory;
  for (auto _ : state) {
    memory.Start();
    auto out = leaves.Render(s.camera);
    out.image.backward(v_image);
    Sync();
    peak = std::max(peak, memory.GrowthMiB());
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


// The console output, then a markdown table: one row per size, forward,
// backward, both, and the peak memory of forward + backward.
class MarkdownReporter : public benchmark::ConsoleReporter {
 public:
  MarkdownReporter() : ConsoleReporter(OO_Tabular) {}
  void ReportRuns(const std::vector<Run>& runs) override {
    ConsoleReporter::ReportRuns(runs);
    static const std::regex name(R"(BM_Splat(\w+)/N:(\d+)/side:(\d+)/C:(\d+))");
    for (const Run& run : runs) {
      std::smatch m;
      const std::string full = run.benchmark_name();
      if (run.error_occurred || !std::regex_search(full, m, name)) continue;
      Row& row = rows_[{std::stoll(m[4]), std::stoll(m[2]), std::stoll(m[3])}];
      const double ms = run.GetAdjustedRealTime();
      if (m[1] == "Forward") row.forward = ms;
      if (m[1] == "Backward") row.backward = ms;
      if (m[1] == "ForwardBackward") {
        row.both = ms;
        const auto peak = run.counters.find("peak_MiB");
        if (peak != run.counters.end()) row.peak_mib = peak->second.value;
      }
    }
  }
  void Finalize() override {
    ConsoleReporter::Finalize();
    auto& out = GetOutputStream();
    out << "\n| C | N | image | forward | backward | forward + backward | peak memory |\n"
        << "|---|---|---|---|---|---|---|\n";
    auto cell = [](double v, const char* unit) {
      if (v < 0) return std::string("-");
      char text[32];
      std::snprintf(text, sizeof(text), v < 10 ? "%.1f %s" : "%.0f %s", v, unit);
      return std::string(text);
    };
    for (const auto& [key, row] : rows_) {
      const auto& [channels, n, side] = key;
      out << "| " << channels << " | " << n / 1000 << "k | " << side << "² | " << cell(row.forward, "ms")
          << " | " << cell(row.backward, "ms") << " | " << cell(row.both, "ms") << " | "
          << cell(row.peak_mib, "MiB") << " |\n";
    }
  }

 private:
  struct Row {
    double forward = -1, backward = -1, both = -1, peak_mib = -1;
  };
  std::map<std::tuple<int64_t, int64_t, int64_t>, Row> rows_;
};

}  // namespace
}  // namespace headforge

int main(int argc, char** argv) {
  // Large blocks straight from and back to the system, so that resident memory
  // follows what is allocated and the per-iteration peak is meaningful.
  mallopt(M_MMAP_THRESHOLD, 256 * 1024);
  mallopt(M_TRIM_THRESHOLD, 256 * 1024);
  headforge::ConfigureTorchThreads(headforge::HardwareThreads());
  headforge::UseTensorThreads();
  bool markdown = false;
  for (int i = 1; i < argc;) {
    const std::string arg = argv[i];
    if (arg == "--markdown") {
      markdown = true;
    } else if (arg.rfind("--device=", 0) == 0) {
      try {
        headforge::g_device = torch::Device(arg.substr(9));
      } catch (const c10::Error&) {
        std::fprintf(stderr, "--device: not a device: %s (try cpu or cuda)\n", arg.c_str() + 9);
        return 1;
      }
      if (headforge::g_device.is_cuda() && !torch::cuda::is_available()) {
        std::fprintf(stderr, "--device=%s: no CUDA device is visible to LibTorch\n",
                     arg.c_str() + 9);
        return 1;
      }
      if (headforge::g_device.is_cuda() && !headforge::g_device.has_index()) {
        headforge::g_device.set_index(0);
      }
    } else {
      ++i;
      continue;
    }
    for (int j = i; j + 1 < argc; ++j) argv[j] = argv[j + 1];
    --argc;
  }
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::AddCustomContext("torch", headforge::TorchDescription());
  benchmark::AddCustomContext("threads", std::to_string(headforge::HardwareThreads()));
  benchmark::AddCustomContext("device", headforge::g_device.str());
  if (markdown) {
    headforge::MarkdownReporter reporter;
    benchmark::RunSpecifiedBenchmarks(&reporter);
  } else {
    benchmark::RunSpecifiedBenchmarks();
  }
  benchmark::Shutdown();
  return 0;
}
