// FitSplats on a small synthetic scene whose truth is known: a cloud of
// Gaussians rendered from a ring of cameras. Runs on KernelDevice() (the GPU
// in avatar_cuda_test), so the fitting loop, Adam and densification are
// checked on every device the kernels have.
#include <nlohmann/json.hpp>

#include <algorithm>

#include <cmath>
#include <cstdio>
#include <vector>

#include "avatar/metrics/image_metrics.h"
#include "avatar/train/splat_fit.h"
#include "core/interrupt.h"
#include "avatar/splat/splat_test_util.h"

namespace headforge::splat_test {
namespace {

TEST(SplatFit, FitsASyntheticSceneOnTheKernelDevice) {
  // The truth: 400 Gaussians in a 0.4 m cube, opaque enough to hide the
  // black background, seen by 16 cameras at 1.5 m; every 4th is held out.
  auto gen = at::detail::createCPUGenerator(31);
  const auto opts = torch::TensorOptions().dtype(torch::kFloat32);
  const int64_t n = 400;
  GaussianParams truth;
  truth.means = torch::rand({n, 3}, gen, opts) * 0.4 - 0.2;
  truth.quats = torch::randn({n, 4}, gen, opts);
  truth.log_scales = torch::rand({n, 3}, gen, opts) * std::log(2.5) + std::log(0.012);
  truth.opacity_logits = torch::full({n}, 2.0, opts);
  truth.colour_logits = torch::randn({n, 3}, gen, opts) * 1.5;
  std::vector<PosedImage> train, test;
  for (int i = 0; i < 16; ++i) {
    const SplatCamera camera = RingCamera(2 * M_PI * i / 16, 1.5, 64);
    PosedImage view{camera, RenderFitted(truth, camera), "view" + std::to_string(i)};
    (i % 4 == 3 ? test : train).push_back(view);
  }
  // The starting points: the truth's centres 1 cm off, grey, 2 cm wide.
  InitPoints init;
  init.positions = truth.means + torch::randn({n, 3}, gen, opts) * 0.01;
  init.colours = torch::full({n, 3}, 0.5, opts);
  init.sizes = torch::full({n}, 0.02, opts);
  GaussianParams start;
  start.means = init.positions;
  start.quats = torch::zeros({n, 4}, opts);
  start.quats.select(1, 0).fill_(1.0);
  start.log_scales = torch::full({n, 3}, std::log(0.02), opts);
  start.opacity_logits = torch::full({n}, std::log(0.1 / 0.9), opts);
  start.colour_logits = torch::zeros({n, 3}, opts);
  double start_psnr = 0;
  for (const PosedImage& v : test) start_psnr += Psnr(RenderFitted(start, v.camera), v.image) / test.size();

  SplatFitOptions options;
  options.iterations = 600;
  options.device = KernelDevice().str();
  options.log_every = 100;
  options.eval_every = 300;
  options.lr_means = 1.6e-4;
  options.densify.start = 100;
  options.densify.interval = 100;
  options.densify.stop = 400;
  options.densify.max_gaussians = 1600;
  options.densify.reset_every = 0;
  options.densify.scene_extent = 0.4;
  StatsLog stats;
  NullProgress progress;
  SplatFitResult result;
  const Status status = FitSplats(options, train, test, init, &stats, &progress, &result);
  ASSERT_TRUE(status.ok()) << status.message();
  std::vector<nlohmann::json> lines;
  for (const std::string& line : stats.lines()) lines.push_back(nlohmann::json::parse(line));
  std::printf("splat fit on %s: held-out PSNR %.2f -> %.2f dB, SSIM %.3f, %lld Gaussians\n",
              options.device.c_str(), start_psnr, result.test_psnr, result.test_ssim,
              static_cast<long long>(result.params.size()));
  EXPECT_EQ(result.steps, 600);
  // The held-out views: from a blur of grey blobs to the scene.
  EXPECT_LT(start_psnr, 20.0);
  EXPECT_GT(result.test_psnr, 30.0) << "started at " << start_psnr << " dB";
  EXPECT_GT(result.test_ssim, 0.95);
  ASSERT_EQ(result.view_psnr.size(), test.size());
  // Results on the CPU whatever the device; densification changed the count.
  for (torch::Tensor* t : result.params.All()) EXPECT_TRUE(t->device().is_cpu());
  EXPECT_NE(result.params.size(), n);
  ASSERT_EQ(result.test_renders.size(), test.size());
  EXPECT_TRUE(result.test_renders[0].device().is_cpu());
  // The loss curve (a line every 100 steps) falls: the last loss well under
  // the first. Held-out evaluations at step 300 and at the end.
  std::vector<double> losses;
  int evaluations = 0;
  for (const nlohmann::json& line : lines) {
    if (line.contains("loss")) losses.push_back(line["loss"].get<double>());
    evaluations += line.contains("test_psnr");
  }
  ASSERT_EQ(losses.size(), 6u);
  EXPECT_EQ(evaluations, 2);
  EXPECT_LT(losses.back(), 0.5 * losses.front());
}

TEST(SplatFit, AnUnknownOrMissingDeviceIsAClearError) {
  SplatFitOptions options;
  options.iterations = 1;
  InitPoints init;
  init.positions = torch::zeros({1, 3});
  init.colours = torch::full({1, 3}, 0.5);
  init.sizes = torch::full({1}, 0.01);
  const std::vector<PosedImage> views = {
      {RingCamera(0, 1.0, 16), torch::zeros({3, 16, 16}), "v"}};
  NullProgress progress;
  StatsLog stats;
  SplatFitResult result;
  options.device = "toaster";
  Status s = FitSplats(options, views, {}, init, &stats, &progress, &result);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("not a device"), std::string::npos) << s.message();
  if (!torch::cuda::is_available()) {
    options.device = "cuda";
    s = FitSplats(options, views, {}, init, &stats, &progress, &result);
    EXPECT_FALSE(s.ok());
    EXPECT_NE(s.message().find("sees no CUDA device"), std::string::npos) << s.message();
  } else {
    options.device = "cuda:" + std::to_string(torch::cuda::device_count());
    s = FitSplats(options, views, {}, init, &stats, &progress, &result);
    EXPECT_FALSE(s.ok());
    EXPECT_NE(s.message().find("CUDA device(s) are visible"), std::string::npos) << s.message();
  }
}

// Asks the fit to stop (as SIGINT would) once it has done `at` steps.
class StopAt : public NullProgress {
 public:
  explicit StopAt(int64_t at) : at_(at) {}
  void Advance(int64_t units) override {
    done_ += units;
    if (done_ >= at_) RequestInterrupt();
  }

 private:
  int64_t at_, done_ = 0;
};

// A fit stopped on a signal saves a checkpoint and says so; run again with
// the same options it continues from that step and ends with the very
// parameters and statistics of a fit that never stopped.
TEST(SplatFit, InterruptedFitResumesToTheSameResult) {
  auto gen = at::detail::createCPUGenerator(5);
  const auto opts = torch::TensorOptions().dtype(torch::kFloat32);
  const int64_t n = 200;
  GaussianParams truth;
  truth.means = torch::rand({n, 3}, gen, opts) * 0.4 - 0.2;
  truth.quats = torch::randn({n, 4}, gen, opts);
  truth.log_scales = torch::rand({n, 3}, gen, opts) + std::log(0.015);
  truth.opacity_logits = torch::full({n}, 2.0, opts);
  truth.colour_logits = torch::randn({n, 3}, gen, opts);
  std::vector<PosedImage> train;
  for (int i = 0; i < 8; ++i) {
    const SplatCamera camera = RingCamera(2 * M_PI * i / 8, 1.5, 32);
    train.push_back({camera, RenderFitted(truth, camera), "view" + std::to_string(i)});
  }
  InitPoints init;
  init.positions = truth.means + torch::randn({n, 3}, gen, opts) * 0.01;
  init.colours = torch::full({n, 3}, 0.5, opts);
  init.sizes = torch::full({n}, 0.02, opts);
  SplatFitOptions options;
  options.iterations = 300;
  options.device = KernelDevice().str();
  options.log_every = 25;
  options.eval_every = 0;
  options.checkpoint_every = 70;
  options.densify.start = 50;
  options.densify.interval = 50;
  options.densify.stop = 250;
  options.densify.reset_every = 150;
  options.densify.scene_extent = 0.4;
  options.densify.grad_threshold = 0.0001;
  const fs::path dir = fs::temp_directory_path() / "hf_splat_fit_resume";
  fs::remove_all(dir);
  fs::create_directories(dir);

  options.checkpoint_path = (dir / "whole.pt").string();
  StatsLog whole_stats;
  NullProgress quiet;
  SplatFitResult whole;
  {
    InterruptScope scope;
    ASSERT_TRUE(FitSplats(options, train, {}, init, &whole_stats, &quiet, &whole).ok());
  }
  EXPECT_EQ(whole.resumed_from, 0);

  options.checkpoint_path = (dir / "cut.pt").string();
  StatsLog cut_stats;
  ASSERT_TRUE(StatsLog::Open(dir / "stats.jsonl", &cut_stats).ok());
  SplatFitResult cut;
  {
    InterruptScope scope;
    StopAt stop(180);
    const Status stopped = FitSplats(options, train, {}, init, &cut_stats, &stop, &cut);
    EXPECT_EQ(stopped.code(), Status::Code::kInterrupted) << stopped.message();
    EXPECT_NE(stopped.message().find("step 180"), std::string::npos) << stopped.message();
  }
  ASSERT_TRUE(fs::exists(dir / "cut.pt"));
  // The next attempt reads the file back as a fresh process would.
  StatsLog reopened;
  ASSERT_TRUE(StatsLog::Open(dir / "stats.jsonl", &reopened).ok());
  reopened.Append("{\"written after the checkpoint\": true}");
  {
    InterruptScope scope;
    const Status resumed = FitSplats(options, train, {}, init, &reopened, &quiet, &cut);
    ASSERT_TRUE(resumed.ok()) << resumed.message();
  }
  EXPECT_EQ(cut.resumed_from, 180);
  EXPECT_EQ(cut.steps, 300);
  ASSERT_EQ(cut.params.size(), whole.params.size());
  EXPECT_GT(whole.params.size(), n);  // densification ran before and after the cut
  const auto a = whole.params.All(), b = cut.params.All();
  for (size_t i = 0; i < a.size(); ++i) EXPECT_TRUE(torch::equal(*a[i], *b[i])) << "parameter " << i;
  // The statistics are the uninterrupted fit's, apart from the wall time.
  ASSERT_EQ(reopened.size(), whole_stats.size());
  for (size_t i = 0; i < whole_stats.size(); ++i) {
    nlohmann::json x = nlohmann::json::parse(whole_stats.lines()[i]), y = nlohmann::json::parse(reopened.lines()[i]);
    x.erase("seconds");
    y.erase("seconds");
    EXPECT_EQ(x, y) << "line " << i;
  }
  std::string file;
  ASSERT_TRUE(ReadFileToString(dir / "stats.jsonl", &file).ok());
  EXPECT_EQ(std::count(file.begin(), file.end(), '\n'), long(whole_stats.size()));

  // A damaged checkpoint is refused with a way out.
  ASSERT_TRUE(WriteFileAtomic(dir / "cut.pt", "not a checkpoint").ok());
  StatsLog again;
  const Status damaged = FitSplats(options, train, {}, init, &again, &quiet, &cut);
  EXPECT_EQ(damaged.code(), Status::Code::kDataError);
  EXPECT_NE(damaged.message().find("delete it"), std::string::npos) << damaged.message();
}

}  // namespace
}  // namespace headforge::splat_test
