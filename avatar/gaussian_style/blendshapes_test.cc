// The linear fit behind the Gaussian blendshapes, against exactly linear
// data, and posing the blendshapes against the weighted sum written out.
#include "avatar/gaussian_style/blendshapes.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "avatar/splat/splat_test_util.h"
#include "avatar/tensor_test_util.h"
#include "core/progress.h"

namespace headforge {
namespace {


TEST(GaussianBlendshapes, TheFitRecoversAnExactlyLinearMap) {
  torch::manual_seed(4);
  const torch::Tensor x = torch::rand({60, 5}, kDouble);
  const torch::Tensor slopes = torch::randn({5, 7}, kDouble), intercept = torch::randn({1, 7}, kDouble);
  const torch::Tensor y = intercept + x.matmul(slopes);
  const torch::Tensor fit = FitLinearModel(x, y, 0.0);
  ASSERT_EQ(fit.sizes(), (std::vector<int64_t>{6, 7}));
  EXPECT_LT((fit[0] - intercept[0]).abs().max().item<double>(), 1e-10);
  EXPECT_LT((fit.slice(0, 1) - slopes).abs().max().item<double>(), 1e-10);
  // Float32 samples (as posed avatars give them) are fitted in float64.
  const torch::Tensor fit32 = FitLinearModel(x.to(torch::kFloat32), y.to(torch::kFloat32), 0.0);
  EXPECT_EQ(fit32.scalar_type(), torch::kFloat64);
  EXPECT_LT((fit32.slice(0, 1) - slopes).abs().max().item<double>(), 1e-4);
}

// Two expressions that always move together (as two tracked blendshapes may
// over a clip) leave their split loose: the damping shares it and the fit
// still gives the outputs.
TEST(GaussianBlendshapes, TiedInputsStayFiniteWithDamping) {
  torch::manual_seed(5);
  torch::Tensor x = torch::rand({40, 3}, kDouble);
  x.select(1, 2).copy_(x.select(1, 1));
  const torch::Tensor y = 0.3 + 2.0 * x.select(1, 0).unsqueeze(1) + 1.0 * x.select(1, 1).unsqueeze(1);
  const torch::Tensor fit = FitLinearModel(x, y, 1e-6);
  EXPECT_TRUE(torch::isfinite(fit).all().item<bool>());
  EXPECT_NEAR(fit[2][0].item<double>(), fit[3][0].item<double>(), 1e-3);  // shared evenly
  const torch::Tensor predicted = fit[0] + x.matmul(fit.slice(0, 1));
  EXPECT_LT((predicted - y).abs().max().item<double>(), 1e-3);
}

TEST(GaussianBlendshapes, PosingIsTheNeutralPlusTheWeightedOffsets) {
  torch::manual_seed(6);
  GaussianBlendshapes shapes;
  shapes.neutral = torch::rand({4, kBlendshapeAttributes});
  shapes.offsets = torch::randn({2, 4, kBlendshapeAttributes}) * 0.1;
  shapes.opacities = torch::rand({4});
  const torch::Tensor w = torch::tensor({0.25f, 0.5f});
  const PosedGaussians posed = PoseBlendshapes(shapes, w);
  const torch::Tensor expected = shapes.neutral + 0.25 * shapes.offsets[0] + 0.5 * shapes.offsets[1];
  EXPECT_TRUE(torch::allclose(posed.means, expected.slice(1, 0, 3), 1e-6, 1e-6));
  EXPECT_TRUE(torch::allclose(posed.quats, expected.slice(1, 3, 7), 1e-6, 1e-6));
  EXPECT_TRUE(torch::allclose(posed.log_scales, expected.slice(1, 7, 10), 1e-6, 1e-6));
  EXPECT_TRUE(torch::allclose(posed.features, expected.slice(1, 10, 13).clamp(0, 1), 1e-6, 1e-6));
  EXPECT_TRUE(torch::equal(posed.opacities, shapes.opacities));
}

double Psnr(const torch::Tensor& a, const torch::Tensor& b) {
  return -10 * std::log10((a - b).pow(2).mean().item<double>());
}

// n Gaussians of 2 cm in a 30 cm cube, random rotations and colours, at
// rest (neutral only): what the refinement and pruning tests start from.
torch::Tensor RandomNeutral(int64_t n, at::Generator& gen) {
  torch::Tensor neutral = torch::zeros({n, kBlendshapeAttributes});
  neutral.slice(1, 0, 3).copy_(torch::rand({n, 3}, gen) * 0.3 - 0.15);
  neutral.slice(1, 3, 7).copy_(torch::randn({n, 4}, gen));
  neutral.slice(1, 7, 10).fill_(std::log(0.02));
  neutral.slice(1, 10, 13).copy_(torch::rand({n, 3}, gen));
  return neutral;
}

// Blendshapes whose colours and expression offsets the fit got wrong are
// refined through the rasterizer against frames of the true ones: views
// never trained on come closer to the truth, the views set aside judge it,
// and what is kept stays a valid avatar.
TEST(GaussianBlendshapes, RefinementAgainstTheFramesRecoversWhatTheFitMissed) {
  auto gen = at::detail::createCPUGenerator(21);
  const int64_t n = 300, k = 2;
  GaussianBlendshapes truth;
  truth.neutral = RandomNeutral(n, gen);
  truth.offsets = torch::zeros({k, n, kBlendshapeAttributes});
  truth.offsets[0].slice(1, 0, 1).fill_(0.03);                    // expression 0 moves every Gaussian in x
  truth.offsets[1].slice(1, 10, 13).copy_(torch::rand({n, 3}, gen) * 0.6 - 0.3);  // expression 1 recolours
  truth.opacities = torch::full({n}, 0.9f);
  truth.names = {"a", "b"};

  // 40 views round the truth at random expressions: 30 to refine on, 10
  // never seen. A view's mask is the truth's coverage and its image the
  // colour under it, so that image * mask + background * (1 - mask) is the
  // truth drawn over that background, as the refinement composes it.
  AvatarDataset data;
  std::vector<torch::Tensor> test_truth;  // drawn over black
  const torch::Tensor black = torch::zeros({3}), white_features = torch::ones({n, 3});
  for (int i = 0; i < 40; ++i) {
    AvatarView view;
    view.view = splat_test::RingCamera(2 * M_PI * i / 40, 1.0, 40);
    view.condition = torch::cat({torch::rand({k}, gen), torch::zeros({9})});
    PosedGaussians posed = PoseBlendshapes(truth, view.condition.slice(0, 0, k));
    const torch::Tensor drawn = RenderRgb(posed, view.view, black);
    posed.features = white_features;
    view.mask = RenderRgb(posed, view.view, black).select(0, 0).unsqueeze(0).clamp(0, 1);
    view.image = (drawn / view.mask.clamp_min(1e-4)).clamp(0, 1);
    if (i % 4 == 1) {
      data.test.push_back(view);
      test_truth.push_back(drawn);
    } else {
      data.train.push_back(view);
    }
  }
  // What a fit might leave: colours off by up to 0.15, the recolouring missed.
  GaussianBlendshapes start = truth;
  start.neutral = truth.neutral.clone();
  start.neutral.slice(1, 10, 13).add_(torch::rand({n, 3}, gen) * 0.3 - 0.15);
  start.offsets = truth.offsets.clone();
  start.offsets[1].zero_();
  auto held_out = [&](const GaussianBlendshapes& shapes) {
    double sum = 0;
    for (size_t i = 0; i < data.test.size(); ++i) {
      const AvatarView& view = data.test[i];
      sum += Psnr(RenderRgb(PoseBlendshapes(shapes, view.condition.slice(0, 0, k)), view.view, black), test_truth[i]);
    }
    return sum / double(data.test.size());
  };
  const double before = held_out(start);

  BlendshapeRefineOptions options;
  options.steps = 200;
  options.lr_scale = 4.0;
  options.eval_every = 50;
  GaussianBlendshapes refined = start;
  BlendshapeRefineReport report;
  NullProgress progress;
  ASSERT_TRUE(RefineBlendshapes(data, options, &refined, &report, &progress).ok());
  const double after = held_out(refined);
  EXPECT_GT(after, before + 3.0) << before << " -> " << after << " dB on views never refined on";
  EXPECT_EQ(report.steps, 200);
  EXPECT_EQ(report.validation_views, 3);  // every 10th of the 30
  EXPECT_GT(report.kept_step, 0);
  EXPECT_GT(report.validation_psnr_after, report.validation_psnr_before + 3.0);
  ASSERT_EQ(report.curve.size(), 5u);  // before, steps 50, 100 and 150, and the last
  EXPECT_EQ(report.curve.front().first, 0);
  EXPECT_DOUBLE_EQ(report.curve.front().second, report.validation_psnr_before);
  EXPECT_EQ(refined.neutral.sizes(), start.neutral.sizes());
  EXPECT_EQ(refined.offsets.sizes(), start.offsets.sizes());
  EXPECT_TRUE(torch::isfinite(refined.neutral).all().item<bool>());
  EXPECT_GE(refined.opacities.min().item<float>(), 0.0f);
  EXPECT_LE(refined.opacities.max().item<float>(), 1.0f);
  EXPECT_EQ(refined.names, start.names);

  // No steps: nothing changes.
  GaussianBlendshapes same = start;
  options.steps = 0;
  ASSERT_TRUE(RefineBlendshapes(data, options, &same, &report, &progress).ok());
  EXPECT_TRUE(torch::equal(same.neutral, start.neutral));
  EXPECT_EQ(report.steps, 0);
  // Bad settings and too few views are refused, the blendshapes untouched.
  options.steps = 10;
  options.validation = 0;
  EXPECT_FALSE(RefineBlendshapes(data, options, &same, &report, &progress).ok());
  options.validation = 0.1;
  AvatarDataset one;
  one.train = {data.train.front()};
  const Status few = RefineBlendshapes(one, options, &same, &report, &progress);
  EXPECT_FALSE(few.ok());
  EXPECT_NE(few.message().find("too few"), std::string::npos) << few.message();
  EXPECT_TRUE(torch::equal(same.neutral, start.neutral));
}

// Pruning drops the Gaussians that give no light: 60 that draw the views
// among 20 outside every view and 20 all but transparent. The two fifths
// removed are exactly those, the rest in the order they had, the views drawn
// as before; bad fractions are refused.
TEST(GaussianBlendshapes, PruningRemovesTheGaussiansThatGiveNoLight) {
  auto gen = at::detail::createCPUGenerator(22);
  const int64_t real = 60, n = 100, k = 2;
  GaussianBlendshapes shapes;
  shapes.neutral = RandomNeutral(n, gen);
  shapes.offsets = torch::randn({k, n, kBlendshapeAttributes}, gen) * 0.01;
  shapes.opacities = torch::full({n}, 0.9f);
  shapes.names = {"a", "b"};
  // Gaussians 60..79 two metres above the ring (its cameras see 23 deg
  // either side), 80..99 at opacity 1e-4; interleaved with the others by a
  // permutation, so that order is tested too.
  const torch::Tensor order = torch::randperm(n, gen);
  std::vector<int64_t> junk;
  for (int64_t i = 0; i < n; ++i) {
    const int64_t at = order[i].item<int64_t>();
    if (i >= real) junk.push_back(at);
    if (i >= real && i < 80) shapes.neutral[at][1] = 2.0;
    if (i >= 80) shapes.opacities[at] = 1e-4f;
  }
  AvatarDataset data;
  for (int i = 0; i < 16; ++i) {
    AvatarView view;
    view.view = splat_test::RingCamera(2 * M_PI * i / 16, 1.0, 40);
    view.condition = torch::cat({torch::rand({k}, gen), torch::zeros({9})});
    data.train.push_back(view);
  }
  GaussianBlendshapes pruned = shapes;
  BlendshapePruneReport report;
  ASSERT_TRUE(PruneBlendshapes(data, 0.4, &pruned, &report).ok());
  EXPECT_EQ(report.before, 100);
  EXPECT_EQ(report.after, 60);
  EXPECT_GT(report.light_kept, 0.999);
  std::vector<int64_t> kept;
  for (int64_t i = 0; i < n; ++i)
    if (std::find(junk.begin(), junk.end(), i) == junk.end()) kept.push_back(i);
  const torch::Tensor index = torch::tensor(kept);
  EXPECT_TRUE(torch::equal(pruned.neutral, shapes.neutral.index_select(0, index)));
  EXPECT_TRUE(torch::equal(pruned.offsets, shapes.offsets.index_select(1, index)));
  EXPECT_TRUE(torch::equal(pruned.opacities, shapes.opacities.index_select(0, index)));
  const torch::Tensor grey = torch::full({3}, 0.5f);
  for (const AvatarView& view : data.train) {
    const torch::Tensor w = view.condition.slice(0, 0, k);
    const double psnr =
        Psnr(RenderRgb(PoseBlendshapes(pruned, w), view.view, grey), RenderRgb(PoseBlendshapes(shapes, w), view.view, grey));
    EXPECT_GT(psnr, 50.0);
  }
  // Nothing removed at 0; a fraction outside [0, 1) refused, nothing touched.
  GaussianBlendshapes same = shapes;
  ASSERT_TRUE(PruneBlendshapes(data, 0.0, &same, &report).ok());
  EXPECT_TRUE(torch::equal(same.neutral, shapes.neutral));
  EXPECT_EQ(report.after, 100);
  EXPECT_FALSE(PruneBlendshapes(data, 1.0, &same, &report).ok());
  EXPECT_FALSE(PruneBlendshapes(data, -0.1, &same, &report).ok());
  EXPECT_EQ(same.neutral.size(0), 100);
}

}  // namespace
}  // namespace headforge
