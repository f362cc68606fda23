// The linear fit behind the Gaussian blendshapes, against exactly linear
// data, and posing the blendshapes against the weighted sum written out.
#include "avatar/gaussian_style/blendshapes.h"

#include <gtest/gtest.h>

namespace headforge {
namespace {

const auto kDouble = torch::TensorOptions().dtype(torch::kFloat64);

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

}  // namespace
}  // namespace headforge
