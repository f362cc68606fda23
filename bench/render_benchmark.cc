// Rendering speed of the simulator on this machine: one 512x512 frame of the
// full ICT head (26.7k vertices, 52k triangles) with a textured backdrop.
//   build/bench/headforge_bench --benchmark_filter=Render
#include <benchmark/benchmark.h>

#include "capture/simulator.h"
#include "core/parallel.h"
#include "core/paths.h"

namespace headforge {
namespace {

const FaceModel& Model() {
  static FaceModel* model = [] {
    auto* m = new FaceModel();
    const Status s = FaceModel::Load(DefaultDataDir() + "/ict_facekit/ict_face_model.h5", m);
    if (!s.ok()) throw std::runtime_error(s.message());
    return m;
  }();
  return *model;
}

std::unique_ptr<Simulator> MakeSimulator(int resolution, int supersample, bool lighting) {
  const std::string text = std::string("name = \"bench\"\nfps = 25\nduration = 1.0\n") +
                           (lighting ? "effects = [\"lighting\"]\n" : "effects = []\n") +
                           "[render]\nsupersample = " + std::to_string(supersample) +
                           "\n[background]\ntype = \"backdrop\"\n[camera]\nposition = [0.0, 0.0, 0.65]\n"
                           "[camera.intrinsics]\nwidth = " + std::to_string(resolution) +
                           "\nheight = " + std::to_string(resolution) +
                           "\nfov_deg = 30.0\n[expressions]\njawOpen = 0.3\n";
  Scene scene;
  if (!ParseScene(text, "bench", &scene).ok()) throw std::runtime_error("bench scene");
  std::unique_ptr<Simulator> sim;
  if (!Simulator::Create(scene, Model(), HardwareThreads(), &sim).ok()) throw std::runtime_error("simulator");
  return sim;
}

// One frame: expression evaluation, normals, rasterisation, shading, 8-bit output.
void BM_RenderHeadFrame(benchmark::State& state) {
  const auto sim = MakeSimulator(static_cast<int>(state.range(0)), static_cast<int>(state.range(1)),
                                 state.range(2) != 0);
  int frame = 0;
  for (auto _ : state) {
    SimulatedView view = sim->RenderView(frame++ % 25, 0);
    benchmark::DoNotOptimize(view.image.data);
  }
  state.SetLabel(std::to_string(state.range(0)) + "px, " + std::to_string(state.range(1)) + "x" +
                 std::to_string(state.range(1)) + " samples" + (state.range(2) ? ", lit" : ""));
}
BENCHMARK(BM_RenderHeadFrame)
    ->Args({512, 1, 0})
    ->Args({512, 3, 0})
    ->Args({512, 3, 1})
    ->Args({1024, 3, 1})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

}  // namespace
}  // namespace headforge

BENCHMARK_MAIN();
