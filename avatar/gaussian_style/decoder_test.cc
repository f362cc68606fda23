// The stage-3 decoder: a fresh decoder is its generator (projections start
// at zero), the square canvas draws the camera's image scaled and centred,
// and generator weights go to a .safetensors file and back.
#include <gtest/gtest.h>
#include <torch/torch.h>

#include "avatar/gaussian_style/decoder.h"
#include "core/safetensors.h"

namespace headforge {
namespace {

StyleDecoderOptions TinyDecoder() {
  StyleDecoderOptions options;
  options.feature_channels = 6;
  options.generator.z_dim = 8;
  options.generator.w_dim = 8;
  options.generator.mapping_layers = 2;
  options.generator.resolution = 32;
  options.generator.channel_base = 64;
  options.generator.min_channels = 4;
  options.generator.max_channels = 8;
  options.projected_blocks = 2;
  return options;
}

TEST(StyleDecoder, AFreshDecoderDrawsWhatItsGeneratorDrawsAtItsLatent) {
  torch::manual_seed(21);
  StyleDecoder decoder(TinyDecoder());
  {
    torch::NoGradGuard no_grad;
    decoder->w.normal_();
    for (auto& item : decoder->generator->named_parameters())
      if (item.key().find("noise_strength") == 0) item.value().fill_(0.2);
  }
  const torch::Tensor splat = torch::rand({2, 6, 32, 32});
  const torch::Tensor decoded = decoder->forward(splat);
  ASSERT_EQ(decoded.sizes(), torch::IntArrayRef({2, 3, 32, 32}));
  const torch::Tensor generated = decoder->Generate(decoder->w.expand({2, -1}));
  EXPECT_TRUE(torch::allclose(decoded, generated, 1e-6, 1e-6)) << (decoded - generated).abs().max();
  // Only the projected blocks (and the input) take the encoder's features: a
  // step on the fusion parameters makes the image follow the splat.
  EXPECT_EQ(decoder->projections->size(), 2u);
  const torch::Tensor loss = (decoder->forward(splat) - splat.slice(1, 0, 3)).abs().mean();
  loss.backward();
  double fused = 0;
  for (const torch::Tensor& t : decoder->FusionParameters())
    if (t.grad().defined()) fused += t.grad().abs().sum().item<double>();
  EXPECT_GT(fused, 0);
}

// Hard inputs: a splat image of zeros (nothing splatted, not even the
// background), one saturated at 1 and one far beyond: the decoded image
// and every gradient stay finite.
TEST(StyleDecoder, ZeroAndSaturatedSplatImagesStayFinite) {
  torch::manual_seed(24);
  StyleDecoder decoder(TinyDecoder());
  {
    torch::NoGradGuard no_grad;
    for (auto& item : decoder->named_parameters())
      if (item.key().find("second") != std::string::npos) item.value().normal_(0, 0.1);  // projections live
  }
  for (const double value : {0.0, 1.0, 1e4}) {
    const torch::Tensor splat = torch::full({1, 6, 32, 32}, value).requires_grad_(true);
    const torch::Tensor out = decoder->forward(splat);
    ASSERT_TRUE(torch::isfinite(out).all().item<bool>()) << value;
    out.abs().mean().backward();
    EXPECT_TRUE(torch::isfinite(splat.grad()).all().item<bool>()) << value;
    for (const torch::Tensor& t : decoder->FusionParameters())
      if (t.grad().defined()) {
        EXPECT_TRUE(torch::isfinite(t.grad()).all().item<bool>()) << value;
      }
    decoder->zero_grad();
  }
}

TEST(SquareCanvas, DrawsTheCamerasImageScaledAndCentred) {
  SplatCamera camera;
  camera.width = 40;
  camera.height = 30;
  camera.fx = camera.fy = 50;
  camera.cx = 19.5;
  camera.cy = 14.5;
  const SquareCanvas canvas = MakeSquareCanvas(camera, 64);
  EXPECT_EQ(canvas.width, 64);
  EXPECT_EQ(canvas.height, 48);
  EXPECT_EQ(canvas.x0, 0);
  EXPECT_EQ(canvas.y0, 8);
  EXPECT_EQ(canvas.camera.width, 64);
  EXPECT_EQ(canvas.camera.height, 64);
  // A point's pixel on the canvas is its pixel in the image, scaled (pixel
  // centres at integers) and moved by the offset.
  const double x = 0.13, y = -0.07, z = 1.1, scale = 64.0 / 40;
  const double u = camera.fx * x / z + camera.cx, v = camera.fy * y / z + camera.cy;
  EXPECT_NEAR(canvas.camera.fx * x / z + canvas.camera.cx, (u + 0.5) * scale - 0.5 + canvas.x0, 1e-12);
  EXPECT_NEAR(canvas.camera.fy * y / z + canvas.camera.cy, (v + 0.5) * scale - 0.5 + canvas.y0, 1e-12);
}

TEST(GeneratorWeights, GoToASafetensorsFileAndBackAndAWrongShapeIsNamed) {
  const fs::path dir = fs::temp_directory_path() / "hf_generator_weights";
  fs::remove_all(dir);
  fs::create_directories(dir);
  torch::manual_seed(22);
  nn::StyleGenerator a(TinyDecoder().generator);
  torch::manual_seed(23);
  nn::StyleGenerator b(TinyDecoder().generator);
  const torch::Tensor w = torch::randn({1, 8});
  ASSERT_FALSE(torch::allclose(a->Synthesize(w), b->Synthesize(w)));
  ASSERT_TRUE(SaveGeneratorWeights(*a, dir / "generator.safetensors").ok());
  const Status loaded = LoadGeneratorWeights(dir / "generator.safetensors", b.get());
  ASSERT_TRUE(loaded.ok()) << loaded.message();
  EXPECT_TRUE(torch::equal(a->Synthesize(w), b->Synthesize(w)));

  // The layout is the parameter names and shapes: every one is in the file.
  SafeTensorsFile file;
  ASSERT_TRUE(ReadSafetensors(dir / "generator.safetensors", &file).ok());
  EXPECT_EQ(file.tensors.size(), a->parameters().size());
  ASSERT_NE(file.Find("constant"), nullptr);
  EXPECT_EQ(file.Find("constant")->shape, (std::vector<int64_t>{1, 8, 4, 4}));
  ASSERT_NE(file.Find("convs.0.weight"), nullptr);
  ASSERT_NE(file.Find("to_rgb.3.affine.weight"), nullptr);

  // A generator of another size: the error names the tensor that does not fit.
  nn::StyleGeneratorOptions other = TinyDecoder().generator;
  other.max_channels = 16;
  nn::StyleGenerator c(other);
  const Status refused = LoadGeneratorWeights(dir / "generator.safetensors", c.get());
  EXPECT_EQ(refused.code(), Status::Code::kDataError);
  EXPECT_NE(refused.message().find("constant"), std::string::npos) << refused.message();
  fs::remove_all(dir);
}

}  // namespace
}  // namespace headforge
