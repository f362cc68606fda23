// The shared modules against plain references and central finite
// differences, in float64.
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <functional>

#include "avatar/nn/attention.h"
#include "avatar/nn/mlp.h"
#include "avatar/nn/modulated_conv.h"
#include "avatar/nn/stylegan.h"
#include "avatar/nn/triplane.h"
#include "avatar/tensor_test_util.h"

namespace headforge::nn {
namespace {


// The gradient of sum(f(x) * r) for a fixed random r, by autograd and by
// central differences on up to `samples` entries of x.
void ExpectGradientMatchesFiniteDifferences(const std::function<torch::Tensor(const torch::Tensor&)>& f,
                                            const torch::Tensor& x0, double tolerance, int samples = 40) {
  torch::manual_seed(7);
  const torch::Tensor x = x0.detach().clone().requires_grad_(true);
  const torch::Tensor r = torch::randn_like(f(x).detach());
  const torch::Tensor analytic = torch::autograd::grad({(f(x) * r).sum()}, {x})[0];
  const torch::Tensor flat = x.detach().clone().view(-1);
  const int64_t n = flat.numel();
  const double h = 1e-6;
  for (int s = 0; s < samples && s < n; ++s) {
    const int64_t i = (s * 7919) % n;
    torch::Tensor plus = flat.clone(), minus = flat.clone();
    plus[i] += h;
    minus[i] -= h;
    const double numeric = ((f(plus.view(x.sizes())) * r).sum().item<double>() -
                            (f(minus.view(x.sizes())) * r).sum().item<double>()) /
                           (2 * h);
    const double got = analytic.view(-1)[i].item<double>();
    EXPECT_NEAR(got, numeric, tolerance * (1 + std::abs(numeric))) << "entry " << i;
  }
}

TEST(ModulatedConv2d, MatchesScalingTheInputAndTheOutput) {
  // conv(x, W * s) demodulated equals conv(x * s, W) times each output
  // channel's 1 / |W * s|: the reference builds it that way, one sample at a time.
  torch::manual_seed(1);
  ModulatedConv2d conv(5, 4, 3, 6);
  conv->to(torch::kFloat64);
  const torch::Tensor x = torch::randn({3, 5, 7, 6}, kDouble).requires_grad_(true);
  const torch::Tensor w = torch::randn({3, 6}, kDouble);
  const torch::Tensor y = conv->forward(x, w);
  std::vector<torch::Tensor> reference;
  const torch::Tensor s = conv->Style(w);
  for (int64_t b = 0; b < 3; ++b) {
    const torch::Tensor scaled = x[b].unsqueeze(0) * s[b].view({1, 5, 1, 1});
    const torch::Tensor plain = torch::nn::functional::conv2d(scaled, conv->weight,
                                                                 torch::nn::functional::Conv2dFuncOptions().padding(1));
    const torch::Tensor norm = (conv->weight * s[b].view({1, 5, 1, 1})).pow(2).sum({1, 2, 3}).add(1e-8).rsqrt();
    reference.push_back(plain * norm.view({1, 4, 1, 1}) + conv->bias.view({1, 4, 1, 1}));
  }
  const torch::Tensor expected = torch::cat(reference);
  EXPECT_TRUE(torch::allclose(y, expected, 1e-12, 1e-12));
  // Gradients through the input, the weight and the style's affine layer.
  const torch::Tensor r = torch::randn_like(y);
  const auto params = conv->parameters();
  std::vector<torch::Tensor> inputs = {x};
  inputs.insert(inputs.end(), params.begin(), params.end());
  const auto got = torch::autograd::grad({(y * r).sum()}, inputs, {}, true);
  const auto want = torch::autograd::grad({(expected * r).sum()}, inputs);
  for (size_t i = 0; i < got.size(); ++i) EXPECT_TRUE(torch::allclose(got[i], want[i], 1e-10, 1e-12)) << i;
}

TEST(ModulatedConv2d, GradientMatchesFiniteDifferences) {
  torch::manual_seed(2);
  ModulatedConv2d conv(3, 2, 3, 4, false);
  conv->to(torch::kFloat64);
  const torch::Tensor w = torch::randn({2, 4}, kDouble);
  ExpectGradientMatchesFiniteDifferences([&](const torch::Tensor& x) { return conv->forward(x, w); },
                                         torch::randn({2, 3, 5, 5}, kDouble), 1e-6);
  const torch::Tensor x = torch::randn({2, 3, 5, 5}, kDouble);
  ExpectGradientMatchesFiniteDifferences([&](const torch::Tensor& ww) { return conv->forward(x, ww); }, w, 1e-6);
}

// Bilinear look-up written out: pixel centres at (i + 0.5) / R * 2 - 1, the
// coordinate clamped to the border.
torch::Tensor PlainLookUp(const torch::Tensor& plane, const torch::Tensor& u, const torch::Tensor& v) {
  const int64_t r = plane.size(1);
  const torch::Tensor pu = ((u + 1) * r - 1).div(2).clamp(0, r - 1), pv = ((v + 1) * r - 1).div(2).clamp(0, r - 1);
  const torch::Tensor u0 = pu.floor().clamp(0, r - 1), v0 = pv.floor().clamp(0, r - 1);
  const torch::Tensor fu = pu - u0, fv = pv - v0;
  const torch::Tensor i0 = u0.to(torch::kLong), j0 = v0.to(torch::kLong);
  const torch::Tensor i1 = (i0 + 1).clamp_max(r - 1), j1 = (j0 + 1).clamp_max(r - 1);
  auto at = [&](const torch::Tensor& i, const torch::Tensor& j) { return plane.index({torch::indexing::Slice(), j, i}).t(); };
  return at(i0, j0) * ((1 - fu) * (1 - fv)).unsqueeze(1) + at(i1, j0) * (fu * (1 - fv)).unsqueeze(1) +
         at(i0, j1) * ((1 - fu) * fv).unsqueeze(1) + at(i1, j1) * (fu * fv).unsqueeze(1);
}

TEST(Triplane, LookUpMatchesAPlainBilinearReference) {
  torch::manual_seed(3);
  const torch::Tensor planes = torch::randn({3, 4, 8, 8}, kDouble);
  // Inside the planes, and some outside (border values).
  torch::Tensor points = torch::rand({50, 3}, kDouble) * 2 - 1;
  points.slice(0, 0, 5).mul_(1.3);
  const torch::Tensor got = SampleTriplane(planes, points);
  ASSERT_EQ(got.sizes(), torch::IntArrayRef({50, 12}));
  const torch::Tensor x = points.select(1, 0), y = points.select(1, 1), z = points.select(1, 2);
  const torch::Tensor want =
      torch::cat({PlainLookUp(planes[0], x, y), PlainLookUp(planes[1], x, z), PlainLookUp(planes[2], z, y)}, 1);
  EXPECT_TRUE(torch::allclose(got, want, 1e-12, 1e-12)) << (got - want).abs().max();
  // Gradients with respect to the planes and the points (inside, away from texel edges).
  const torch::Tensor inside = points.slice(0, 5) * 0.9;
  ExpectGradientMatchesFiniteDifferences([&](const torch::Tensor& p) { return SampleTriplane(p, inside); }, planes, 1e-7);
  ExpectGradientMatchesFiniteDifferences([&](const torch::Tensor& q) { return SampleTriplane(planes, q); }, inside, 1e-5);
}

TEST(Triplane, ABatchLooksEachSampleUpOnItsOwnPlanes) {
  torch::manual_seed(5);
  const torch::Tensor planes = torch::randn({2, 3, 4, 8, 8}, kDouble);
  const torch::Tensor points = torch::rand({2, 30, 3}, kDouble) * 2.4 - 1.2;
  const torch::Tensor got = SampleTriplane(planes, points);
  ASSERT_EQ(got.sizes(), torch::IntArrayRef({2, 30, 12}));
  for (int64_t b = 0; b < 2; ++b)
    EXPECT_TRUE(torch::allclose(got[b], SampleTriplane(planes[b], points[b]), 1e-14, 1e-14)) << b;
  EXPECT_THROW(SampleTriplane(planes, points[0]), c10::Error);  // batched planes, unbatched points
}

TEST(Triplane, GeneratorMakesPlanesThatFollowTheLatent) {
  torch::manual_seed(4);
  TriplaneGeneratorOptions options;
  options.latent_dim = 8;
  options.w_dim = 16;
  options.channels = 8;
  options.resolution = 16;
  options.plane_channels = 3;
  TriplaneGenerator generator(options);
  const torch::Tensor latent = torch::randn({2, 8});
  const torch::Tensor planes = generator->forward(latent);
  ASSERT_EQ(planes.sizes(), torch::IntArrayRef({2, 3, 3, 16, 16}));
  EXPECT_TRUE(torch::isfinite(planes).all().item<bool>());
  EXPECT_TRUE(torch::equal(generator->forward(latent), planes));  // no noise
  EXPECT_GT((planes[0] - planes[1]).abs().mean().item<double>(), 1e-3);
  const torch::Tensor loss = planes.pow(2).mean();
  loss.backward();
  for (const auto& p : generator->parameters()) {
    ASSERT_TRUE(p.grad().defined());
    EXPECT_TRUE(torch::isfinite(p.grad()).all().item<bool>());
  }
}

TEST(CrossAttentionBlock, GradientsMatchFiniteDifferences) {
  torch::manual_seed(5);
  CrossAttentionBlock block(8, 2, 16);
  block->to(torch::kFloat64);
  const torch::Tensor features = torch::randn({6, 8}, kDouble), tokens = torch::randn({5, 8}, kDouble);
  ExpectGradientMatchesFiniteDifferences([&](const torch::Tensor& f) { return block->forward(f, tokens); }, features,
                                         1e-6);
  ExpectGradientMatchesFiniteDifferences([&](const torch::Tensor& t) { return block->forward(features, t); }, tokens,
                                         1e-6);
  // And one of its weights (the attention's value projection), perturbed in place.
  torch::Tensor weight = block->named_parameters()["attention.v.weight"];
  const torch::Tensor r = torch::randn({6, 8}, kDouble);
  const torch::Tensor analytic = torch::autograd::grad({(block->forward(features, tokens) * r).sum()}, {weight})[0];
  torch::NoGradGuard no_grad;
  for (int64_t i = 0; i < weight.numel(); i += 5) {
    const double saved = weight.view(-1)[i].item<double>(), h = 1e-6;
    weight.view(-1)[i] = saved + h;
    const double plus = (block->forward(features, tokens) * r).sum().item<double>();
    weight.view(-1)[i] = saved - h;
    const double minus = (block->forward(features, tokens) * r).sum().item<double>();
    weight.view(-1)[i] = saved;
    const double numeric = (plus - minus) / (2 * h);
    EXPECT_NEAR(analytic.view(-1)[i].item<double>(), numeric, 1e-6 * (1 + std::abs(numeric))) << i;
  }
  // Each query attends over the tokens independently of the other queries.
  const torch::Tensor all = block->forward(features, tokens);
  const torch::Tensor one = block->forward(features.slice(0, 2, 3), tokens);
  EXPECT_TRUE(torch::allclose(all.slice(0, 2, 3), one, 1e-12, 1e-12));
}

TEST(Mlp, ZeroLastStartsAsZeroAndLearns) {
  Mlp mlp(std::vector<int64_t>{4, 8, 3}, true);
  const torch::Tensor x = torch::randn({5, 4});
  EXPECT_EQ(mlp->forward(x).abs().max().item<double>(), 0.0);
  mlp->forward(x).sum().backward();
  EXPECT_GT(mlp->parameters().back().grad().abs().sum().item<double>(), 0.0);  // the last bias learns
}

// A 3x3 convolution with zero padding written out as loops.
torch::Tensor PlainConv3x3(const torch::Tensor& x, const torch::Tensor& weight, const torch::Tensor& bias) {
  const int64_t in = x.size(0), out = weight.size(0), h = x.size(1), w = x.size(2);
  torch::Tensor y = torch::zeros({out, h, w}, kDouble);
  auto xa = x.accessor<double, 3>();
  auto wa = weight.accessor<double, 4>();
  auto ya = y.accessor<double, 3>();
  for (int64_t o = 0; o < out; ++o)
    for (int64_t r = 0; r < h; ++r)
      for (int64_t c = 0; c < w; ++c) {
        double sum = bias[o].item<double>();
        for (int64_t i = 0; i < in; ++i)
          for (int64_t dy = -1; dy <= 1; ++dy)
            for (int64_t dx = -1; dx <= 1; ++dx)
              if (r + dy >= 0 && r + dy < h && c + dx >= 0 && c + dx < w)
                sum += wa[o][i][dy + 1][dx + 1] * xa[i][r + dy][c + dx];
        ya[o][r][c] = sum;
      }
  return y;
}

TEST(Projection, MatchesPlainConvolutionsAndItsGradientFiniteDifferences) {
  torch::manual_seed(11);
  Projection projection(3, 4);
  projection->to(torch::kFloat64);
  {
    // A fresh projection is zero; give its second convolution weights to test.
    torch::NoGradGuard no_grad;
    EXPECT_EQ(projection->forward(torch::randn({1, 3, 5, 5}, kDouble)).abs().max().item<double>(), 0.0);
    projection->second->weight.normal_();
    projection->second->bias.normal_();
  }
  const torch::Tensor x = torch::randn({2, 3, 5, 6}, kDouble);
  const torch::Tensor got = projection->forward(x);
  for (int64_t b = 0; b < 2; ++b) {
    torch::NoGradGuard no_grad;
    const torch::Tensor h = torch::leaky_relu(
        PlainConv3x3(x[b], projection->first->weight, projection->first->bias), 0.2);
    const torch::Tensor want = PlainConv3x3(h, projection->second->weight, projection->second->bias);
    EXPECT_TRUE(torch::allclose(got[b], want, 1e-12, 1e-12)) << (got[b] - want).abs().max();
  }
  ExpectGradientMatchesFiniteDifferences([&](const torch::Tensor& in) { return projection->forward(in); }, x, 1e-6);
  ExpectGradientMatchesFiniteDifferences(
      [&](const torch::Tensor& weight) {
        return torch::nn::functional::conv2d(
            torch::leaky_relu(torch::nn::functional::conv2d(x, weight, torch::nn::functional::Conv2dFuncOptions()
                                                                           .bias(projection->first->bias)
                                                                           .padding(1)),
                              0.2),
            projection->second->weight,
            torch::nn::functional::Conv2dFuncOptions().bias(projection->second->bias).padding(1));
      },
      projection->first->weight.detach(), 1e-6);
}

StyleGeneratorOptions TinyGenerator() {
  StyleGeneratorOptions options;
  options.z_dim = 6;
  options.w_dim = 5;
  options.mapping_layers = 2;
  options.resolution = 16;
  options.channel_base = 32;
  options.min_channels = 2;
  options.max_channels = 4;
  return options;
}

TEST(StyleGenerator, BlocksChannelsAndTheInputsItTakes) {
  torch::manual_seed(12);
  const StyleGeneratorOptions options = TinyGenerator();
  EXPECT_EQ(options.Blocks(), 3);  // 4, 8, 16 px
  EXPECT_EQ(options.Channels(4), 4);
  EXPECT_EQ(options.Channels(16), 2);
  StyleGenerator generator(options);
  generator->to(torch::kFloat64);
  const torch::Tensor w = generator->Map(torch::randn({2, 6}, kDouble));
  const torch::Tensor image = generator->Synthesize(w);
  ASSERT_EQ(image.sizes(), torch::IntArrayRef({2, 3, 16, 16}));
  // The learned constant given as the input, and zero injections, change nothing.
  const std::vector<torch::Tensor> zeros = {torch::zeros({2, 4, 4, 4}, kDouble), torch::zeros({2, 4, 8, 8}, kDouble),
                                            torch::zeros({2, 2, 16, 16}, kDouble)};
  EXPECT_TRUE(torch::equal(image, generator->Synthesize(w, zeros, generator->constant().expand({2, -1, -1, -1}))));
  // Random noise differs from the fixed noise once the strengths are non-zero.
  for (auto& item : generator->named_parameters())
    if (item.key().find("noise_strength") == 0) item.value().detach().fill_(0.5);
  auto noise = at::detail::createCPUGenerator(3);
  EXPECT_TRUE(torch::equal(generator->Synthesize(w), generator->Synthesize(w)));  // fixed noise: deterministic
  EXPECT_FALSE(torch::allclose(generator->Synthesize(w), generator->Synthesize(w, {}, {}, &noise)));
  // A larger input gives a larger image (the decoder's non-native canvases).
  EXPECT_EQ(generator->Synthesize(w, {}, torch::randn({2, 4, 8, 4}, kDouble)).sizes(),
            torch::IntArrayRef({2, 3, 32, 16}));
}

TEST(StyleGenerator, GradientsMatchFiniteDifferences) {
  torch::manual_seed(13);
  StyleGenerator generator(TinyGenerator());
  generator->to(torch::kFloat64);
  for (auto& item : generator->named_parameters())
    if (item.key().find("noise_strength") == 0) item.value().detach().fill_(0.3);
  const torch::Tensor w = torch::randn({1, 5}, kDouble);
  ExpectGradientMatchesFiniteDifferences([&](const torch::Tensor& ww) { return generator->Synthesize(ww); }, w, 1e-6);
  const torch::Tensor inject = torch::randn({1, 4, 8, 8}, kDouble);
  ExpectGradientMatchesFiniteDifferences(
      [&](const torch::Tensor& i) { return generator->Synthesize(w, {torch::Tensor(), i}); }, inject, 1e-6);
}

TEST(ConvEncoder, GivesEveryBlocksFeatureCoarsestFirst) {
  torch::manual_seed(14);
  const StyleGeneratorOptions options = TinyGenerator();
  ConvEncoder encoder(7, options);
  const std::vector<torch::Tensor> features = encoder->forward(torch::randn({2, 7, 16, 16}));
  ASSERT_EQ(features.size(), 3u);
  for (int b = 0; b < 3; ++b) {
    const int64_t r = options.BlockResolution(b);
    EXPECT_EQ(features[size_t(b)].sizes(), torch::IntArrayRef({2, options.Channels(r), r, r})) << b;
  }
}

}  // namespace
}  // namespace headforge::nn
