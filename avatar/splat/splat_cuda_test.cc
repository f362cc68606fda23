// The CUDA kernels against the CPU kernels, on scenes larger than the
// reference can take; avatar_cuda_test also runs every reference,
// finite-difference and hard-case test with the kernels on the GPU
// (splat_test_util.h). Built only with CUDA; needs a GPU to run.
#include <torch/torch.h>

#include "avatar/splat/splat_test_util.h"

namespace headforge::splat_test {
namespace {

const torch::Device kCpu = torch::kCPU;
const torch::Device kGpu(torch::kCUDA, 0);

TEST(SplatCuda, AGpuIsVisible) {
  ASSERT_TRUE(torch::cuda::is_available())
      << "avatar_cuda_test was built with CUDA but LibTorch sees no GPU";
}

// Gradients of the loss with respect to every input, kernels on `device`.
std::vector<torch::Tensor> GradientsOn(torch::Device device, const Scene& s, const Loss& loss,
                                       bool depth) {
  return Gradients(s, loss, [&](const Scene& x) { return RenderOn(device, x, depth); });
}

// Forward, tile lists and every gradient of the GPU equal the CPU's in
// double, for channel counts that take one, two and three passes of the GPU's
// channel groups (up to 32 channels at a time; the depth adds one).
class SplatCudaChannels : public ::testing::TestWithParam<int> {};

TEST_P(SplatCudaChannels, GpuMatchesCpuInDouble) {
  const int channels = GetParam();
  const Scene s = RandomScene(400, channels, 21, 100, 72);
  const Rendered cpu = RenderOn(kCpu, s, true);
  const Rendered gpu = RenderOn(kGpu, s, true);
  EXPECT_LE(MaxAbsDiff(gpu.image, cpu.image), 1e-12);
  EXPECT_LE(MaxAbsDiff(gpu.alpha, cpu.alpha), 1e-12);
  EXPECT_LE(MaxAbsDiff(gpu.depth, cpu.depth), 1e-11);
  EXPECT_GT((cpu.alpha > 0.5).to(torch::kFloat64).mean().item<double>(), 0.2);

  const auto p_cpu = ProjectGaussians(s.means, s.quats, s.log_scales, s.camera);
  const Scene g = OnDevice(s, kGpu);
  const auto p_gpu = ProjectGaussians(g.means, g.quats, g.log_scales, g.camera);
  EXPECT_TRUE(torch::equal(p_gpu.radii.cpu(), p_cpu.radii));
  const auto t_cpu = IntersectTiles(p_cpu.means2d, p_cpu.radii, p_cpu.depths, 100, 72);
  const auto t_gpu = IntersectTiles(p_gpu.means2d, p_gpu.radii, p_gpu.depths, 100, 72);
  EXPECT_TRUE(torch::equal(t_gpu.tile_offsets.cpu(), t_cpu.tile_offsets));
  EXPECT_TRUE(torch::equal(t_gpu.gaussian_ids.cpu(), t_cpu.gaussian_ids));

  const Loss loss(channels, s.camera.height, s.camera.width, 22);
  const auto gc = GradientsOn(kCpu, s, loss, true);
  const auto gg = GradientsOn(kGpu, s, loss, true);
  for (size_t i = 0; i < gc.size(); ++i) {
    SCOPED_TRACE(kInputNames[i]);
    EXPECT_GT(MaxAbs(gc[i]), 1e-3);
    EXPECT_LE(MaxAbsDiff(gg[i], gc[i]), 1e-10 * std::max(1.0, MaxAbs(gc[i])));
  }
}

INSTANTIATE_TEST_SUITE_P(Channels, SplatCudaChannels, ::testing::Values(1, 3, 32, 70));

// The benchmark's kind of scene, in float: 20k Gaussians at 256^2 with 32
// channels. The GPU's exponential and summation order differ from the CPU's
// vectorised ones, so the two agree to float precision, not bit for bit.
TEST(SplatCuda, GpuMatchesCpuInFloatOnALargeScene) {
  auto gen = at::detail::createCPUGenerator(23);
  const auto opts = torch::TensorOptions().dtype(torch::kFloat32);
  const int64_t n = 20000;
  Scene s;
  s.camera.width = s.camera.height = 256;
  s.camera.fx = s.camera.fy = 0.5 * 256 / std::tan(30.0 * M_PI / 180.0);
  s.camera.cx = s.camera.cy = 127.5;
  const auto xy = torch::rand({n, 2}, gen, opts) * 3.0 - 1.5;
  const auto z = torch::rand({n, 1}, gen, opts) * 2.0 + 2.0;
  s.means = torch::cat({xy, z}, 1);
  s.quats = torch::randn({n, 4}, gen, opts);
  s.log_scales = torch::rand({n, 3}, gen, opts) * std::log(4.0) + std::log(0.005);
  s.opacities = torch::rand({n}, gen, opts) * 0.8 + 0.1;
  s.features = torch::rand({n, 32}, gen, opts);
  s.background = torch::rand({32}, gen, opts);
  for (auto* t : {&s.means, &s.quats, &s.log_scales, &s.opacities, &s.features, &s.background}) {
    t->requires_grad_(true);
  }
  const Rendered cpu = RenderOn(kCpu, s);
  const Rendered gpu = RenderOn(kGpu, s);
  EXPECT_LE(MaxAbsDiff(gpu.image, cpu.image), 2e-4);
  EXPECT_LE(MaxAbsDiff(gpu.alpha, cpu.alpha), 2e-4);
  const Loss loss(32, 256, 256, 24);
  const auto gc = GradientsOn(kCpu, s, loss, false);
  const auto gg = GradientsOn(kGpu, s, loss, false);
  for (size_t i = 0; i < gc.size(); ++i) {
    SCOPED_TRACE(kInputNames[i]);
    // Per Gaussian, relative to the largest gradient of that input.
    EXPECT_LE(MaxAbsDiff(gg[i], gc[i]), 2e-3 * MaxAbs(gc[i]));
  }
}

TEST(SplatCuda, InputsOnTwoDevicesGiveAClearError) {
  const Scene s = RandomScene(10, 3, 25);
  const Scene g = OnDevice(s, kGpu);
  try {
    ProjectGaussians(g.means, s.quats, g.log_scales, s.camera);
    ADD_FAILURE() << "quats on the CPU were accepted with means on the GPU";
  } catch (const c10::Error& e) {
    EXPECT_NE(std::string(e.what()).find("quats is on cpu, expected cuda:0"), std::string::npos)
        << e.what();
  }
  const auto p = ProjectGaussians(g.means, g.quats, g.log_scales, g.camera);
  const auto t = IntersectTiles(p.means2d, p.radii, p.depths, 40, 36);
  EXPECT_THROW(RasterizeGaussians(p.means2d, p.conics, s.features, g.opacities, g.background, t,
                                  40, 36),
               c10::Error);
  EXPECT_THROW(IntersectTiles(p.means2d, p.radii.cpu(), p.depths, 40, 36), c10::Error);
}

}  // namespace
}  // namespace headforge::splat_test
