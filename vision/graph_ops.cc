// The ops of vision/graph_model.h: TensorFlow's semantics (as TensorFlow.js
// implements them) on LibTorch tensors in the graph's layouts. Images are
// NHWC; windowed ops reorder to NCHW for LibTorch and back.
#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "vision/graph_model.h"

namespace headforge {

namespace {

namespace F = torch::nn::functional;
using torch::indexing::Slice;
using Tensors = std::vector<torch::Tensor>;

[[noreturn]] void Fail(const std::string& why) { throw std::runtime_error(why); }

void Need(const Tensors& in, size_t count) {
  if (in.size() < count)
    Fail("expects " + std::to_string(count) + " inputs, has " + std::to_string(in.size()));
}

// An integer tensor's values (shapes, axes, paddings).
std::vector<int64_t> IntsOf(const torch::Tensor& t) {
  const torch::Tensor c = t.to(torch::kCPU).to(torch::kLong).contiguous().view(-1);
  return std::vector<int64_t>(c.data_ptr<int64_t>(), c.data_ptr<int64_t>() + c.numel());
}

int64_t AxisOf(int64_t axis, int64_t rank) {
  if (axis < -rank || axis >= rank) Fail("axis " + std::to_string(axis) + " out of range for rank " + std::to_string(rank));
  return axis < 0 ? axis + rank : axis;
}

torch::ScalarType DtypeOf(const std::string& type) {
  if (type == "DT_FLOAT") return torch::kFloat32;
  if (type == "DT_INT32") return torch::kInt32;
  if (type == "DT_INT64") return torch::kInt64;
  if (type == "DT_BOOL") return torch::kBool;
  Fail("type " + type + " is not supported");
}

torch::Tensor ToNchw(const torch::Tensor& x) {
  if (x.dim() != 4) Fail("expects a 4-d NHWC tensor, has " + std::to_string(x.dim()) + " dimensions");
  return x.permute({0, 3, 1, 2});
}
torch::Tensor ToNhwc(const torch::Tensor& x) { return x.permute({0, 2, 3, 1}); }

void CheckNhwc(const GraphNode& node) {
  if (node.String("data_format", "NHWC") != "NHWC")
    Fail("data format " + node.String("data_format", "") + " (only NHWC graphs are run)");
}

// A window's placement along one axis: stride, dilation and the padding
// before and after, TensorFlow's SAME, VALID or EXPLICIT.
struct Window {
  int64_t stride = 1, dilation = 1, before = 0, after = 0;
};

// Windows along H and W for kernel (kh, kw) on input (h, w).
std::array<Window, 2> Windows(const GraphNode& node, int64_t h, int64_t w, int64_t kh, int64_t kw) {
  const std::vector<int64_t> strides = node.Ints("strides");
  std::vector<int64_t> dilations = node.Ints("dilations");
  if (strides.size() != 4) Fail("strides must have 4 entries");
  if (dilations.empty()) dilations = {1, 1, 1, 1};
  const std::string padding = node.String("padding", "VALID");
  std::array<Window, 2> out;
  const int64_t size[2] = {h, w}, kernel[2] = {kh, kw};
  for (int a = 0; a < 2; ++a) {
    Window& win = out[a];
    win.stride = strides[1 + a];
    win.dilation = dilations[1 + a];
    if (padding == "SAME") {
      const int64_t effective = (kernel[a] - 1) * win.dilation + 1;
      const int64_t outputs = (size[a] + win.stride - 1) / win.stride;
      const int64_t total = std::max<int64_t>((outputs - 1) * win.stride + effective - size[a], 0);
      win.before = total / 2;
      win.after = total - win.before;
    } else if (padding == "EXPLICIT") {
      const std::vector<int64_t> pads = node.Ints("explicit_paddings");
      if (pads.size() != 8) Fail("explicit_paddings must have 8 entries");
      win.before = pads[2 + 2 * a];
      win.after = pads[3 + 2 * a];
    } else if (padding != "VALID") {
      Fail("padding " + padding);
    }
  }
  return out;
}

// Pads an NCHW tensor by the windows' padding with `value`; returns the
// symmetric padding left for the op itself (none: all applied here).
torch::Tensor PadNchw(const torch::Tensor& x, const std::array<Window, 2>& win, double value) {
  if (win[0].before == 0 && win[0].after == 0 && win[1].before == 0 && win[1].after == 0) return x;
  return F::pad(x, F::PadFuncOptions({win[1].before, win[1].after, win[0].before, win[0].after}).value(value));
}

// Conv2D (groups 1) and DepthwiseConv2dNative (groups = channels) in NHWC.
torch::Tensor Convolve(const GraphNode& node, const torch::Tensor& x, const torch::Tensor& filter, bool depthwise) {
  CheckNhwc(node);
  if (filter.dim() != 4) Fail("expects a 4-d filter");
  const int64_t kh = filter.size(0), kw = filter.size(1), in = filter.size(2), out = filter.size(3);
  const torch::Tensor input = ToNchw(x);
  if (input.size(1) != in) Fail("input has " + std::to_string(input.size(1)) + " channels, the filter " + std::to_string(in));
  const auto win = Windows(node, input.size(2), input.size(3), kh, kw);
  torch::Tensor weight;
  if (depthwise)  // [kh, kw, in, mult] -> [in * mult, 1, kh, kw], channel c * mult + m
    weight = filter.reshape({kh, kw, in * out}).permute({2, 0, 1}).unsqueeze(1);
  else  // [kh, kw, in, out] -> [out, in, kh, kw]
    weight = filter.permute({3, 2, 0, 1});
  const std::vector<int64_t> stride = {win[0].stride, win[1].stride}, dilation = {win[0].dilation, win[1].dilation};
  const torch::Tensor y = torch::conv2d(PadNchw(input, win, 0.0), weight.contiguous(), torch::Tensor(), stride,
                                        std::vector<int64_t>{0, 0}, dilation, depthwise ? in : 1);
  return ToNhwc(y);
}

torch::Tensor Prelu(const torch::Tensor& x, const torch::Tensor& alpha) {
  return torch::where(x > 0, x, x * alpha);
}

// _FusedConv2D and FusedDepthwiseConv2dNative: the convolution then its fused
// ops (BiasAdd, then an activation), their arguments after the filter.
Tensors FusedConvolution(const GraphNode& node, const Tensors& in, bool depthwise) {
  Need(in, 2);
  torch::Tensor y = Convolve(node, in[0], in[1], depthwise);
  size_t arg = 2;
  for (const std::string& op : node.Strings("fused_ops")) {
    if (op == "BiasAdd") {
      Need(in, arg + 1);
      y = y + in[arg++];
    } else if (op == "Relu") {
      y = torch::relu(y);
    } else if (op == "Relu6") {
      y = torch::clamp(y, 0.0, 6.0);
    } else if (op == "Prelu") {
      Need(in, arg + 1);
      y = Prelu(y, in[arg++]);
    } else if (op == "LeakyRelu") {
      y = F::leaky_relu(y, F::LeakyReLUFuncOptions().negative_slope(node.Float("leakyrelu_alpha", 0.2)));
    } else if (op == "Sigmoid") {
      y = torch::sigmoid(y);
    } else if (op == "Elu") {
      y = torch::elu(y);
    } else if (op == "Tanh") {
      y = torch::tanh(y);
    } else {
      Fail("fused op " + op + " is not supported");
    }
  }
  return {y};
}

// Conv2DBackpropInput(input_sizes, filter, out_backprop): the transposed convolution.
Tensors TransposedConvolution(const GraphNode& node, const Tensors& in) {
  Need(in, 3);
  CheckNhwc(node);
  const std::vector<int64_t> sizes = IntsOf(in[0]);  // [N, H, W, C] of the result
  const torch::Tensor& filter = in[1];                // [kh, kw, C_result, C_in]
  if (sizes.size() != 4 || filter.dim() != 4) Fail("expects a 4-entry size and a 4-d filter");
  const auto win = Windows(node, sizes[1], sizes[2], filter.size(0), filter.size(1));
  const torch::Tensor weight = filter.permute({3, 2, 0, 1}).contiguous();  // [C_in, C_result, kh, kw]
  const std::vector<int64_t> stride = {win[0].stride, win[1].stride}, dilation = {win[0].dilation, win[1].dilation};
  const std::vector<int64_t> zero = {0, 0};
  torch::Tensor y = torch::conv_transpose2d(ToNchw(in[2]), weight, torch::Tensor(), stride, zero, zero, 1, dilation);
  y = y.index({Slice(), Slice(), Slice(win[0].before, win[0].before + sizes[1]),
               Slice(win[1].before, win[1].before + sizes[2])});
  if (y.size(2) != sizes[1] || y.size(3) != sizes[2]) Fail("the result is smaller than input_sizes");
  return {ToNhwc(y)};
}

Tensors Pool(const GraphNode& node, const Tensors& in, bool max) {
  Need(in, 1);
  CheckNhwc(node);
  const std::vector<int64_t> k = node.Ints("ksize");
  if (k.size() != 4 || k[0] != 1 || k[3] != 1) Fail("ksize must be [1, kh, kw, 1]");
  const torch::Tensor x = ToNchw(in[0]);
  const auto win = Windows(node, x.size(2), x.size(3), k[1], k[2]);
  const std::vector<int64_t> stride = {win[0].stride, win[1].stride};
  if (max)
    return {ToNhwc(torch::max_pool2d(PadNchw(x, win, -std::numeric_limits<double>::infinity()), {k[1], k[2]}, stride))};
  // TensorFlow averages over the window's inside part only.
  const torch::Tensor sum = torch::avg_pool2d(PadNchw(x, win, 0.0), {k[1], k[2]}, stride);
  if (win[0].before + win[0].after + win[1].before + win[1].after == 0) return {ToNhwc(sum)};
  const torch::Tensor ones = torch::ones({1, 1, x.size(2), x.size(3)}, x.options());
  const torch::Tensor inside = torch::avg_pool2d(PadNchw(ones, win, 0.0), {k[1], k[2]}, stride);
  return {ToNhwc(sum / inside)};
}

// TensorFlow's source coordinates of a resize along one axis.
struct Taps {
  torch::Tensor lower, upper, lerp;  // int64 indices and float weights, one per output
};
Taps ResizeTaps(int64_t in, int64_t out, bool align_corners, bool half_pixel, const torch::Device& device) {
  const double scale = align_corners && out > 1 ? double(in - 1) / double(out - 1) : double(in) / double(out);
  std::vector<int64_t> lo(out), hi(out);
  std::vector<float> w(out);
  for (int64_t i = 0; i < out; ++i) {
    const double src = half_pixel ? (i + 0.5) * scale - 0.5 : i * scale;
    const double f = std::floor(src);
    lo[i] = std::clamp<int64_t>(int64_t(f), 0, in - 1);
    hi[i] = std::min<int64_t>(int64_t(std::ceil(src)), in - 1);
    hi[i] = std::max<int64_t>(hi[i], 0);
    w[i] = float(src - f);
  }
  Taps t;
  t.lower = torch::tensor(lo, torch::kLong).to(device);
  t.upper = torch::tensor(hi, torch::kLong).to(device);
  t.lerp = torch::tensor(w, torch::kFloat32).to(device);
  return t;
}

Tensors ResizeBilinear(const GraphNode& node, const Tensors& in) {
  Need(in, 2);
  const torch::Tensor& x = in[0];
  const std::vector<int64_t> size = IntsOf(in[1]);
  if (x.dim() != 4 || size.size() != 2) Fail("expects NHWC and a 2-entry size");
  const bool align = node.Bool("align_corners", false), half = node.Bool("half_pixel_centers", false);
  const Taps ty = ResizeTaps(x.size(1), size[0], align, half, x.device());
  const Taps tx = ResizeTaps(x.size(2), size[1], align, half, x.device());
  const torch::Tensor top = x.index_select(1, ty.lower), bottom = x.index_select(1, ty.upper);
  const torch::Tensor rows = top + (bottom - top) * ty.lerp.view({1, -1, 1, 1});
  const torch::Tensor left = rows.index_select(2, tx.lower), right = rows.index_select(2, tx.upper);
  return {left + (right - left) * tx.lerp.view({1, 1, -1, 1})};
}

Tensors ResizeNearest(const GraphNode& node, const Tensors& in) {
  Need(in, 2);
  const torch::Tensor& x = in[0];
  const std::vector<int64_t> size = IntsOf(in[1]);
  if (x.dim() != 4 || size.size() != 2) Fail("expects NHWC and a 2-entry size");
  const bool align = node.Bool("align_corners", false), half = node.Bool("half_pixel_centers", false);
  auto taps = [&](int64_t from, int64_t to) {
    const double scale = align && to > 1 ? double(from - 1) / (to - 1) : double(from) / to;
    std::vector<int64_t> index(to);
    for (int64_t i = 0; i < to; ++i) {
      const double src = half ? (i + 0.5) * scale : i * scale;
      index[i] = std::min<int64_t>(align ? int64_t(std::round(src)) : int64_t(std::floor(src)), from - 1);
    }
    return torch::tensor(index, torch::kLong).to(x.device());
  };
  return {x.index_select(1, taps(x.size(1), size[0])).index_select(2, taps(x.size(2), size[1]))};
}

Tensors PadOp(const GraphNode& node, const Tensors& in, double value) {
  Need(in, 2);
  const std::vector<int64_t> p = IntsOf(in[1]);
  const int64_t rank = in[0].dim();
  if (static_cast<int64_t>(p.size()) != 2 * rank) Fail("paddings must be [rank, 2]");
  std::vector<int64_t> pads;  // last dimension first, as F::pad takes them
  for (int64_t d = rank - 1; d >= 0; --d) {
    pads.push_back(p[2 * d]);
    pads.push_back(p[2 * d + 1]);
  }
  const std::string mode = node.op == "MirrorPad" ? node.String("mode", "REFLECT") : "CONSTANT";
  if (mode == "CONSTANT") return {F::pad(in[0], F::PadFuncOptions(pads).value(value))};
  // Mirror padding by gathering indices along each padded dimension.
  torch::Tensor y = in[0];
  for (int64_t d = 0; d < rank; ++d) {
    const int64_t before = p[2 * d], after = p[2 * d + 1], n = y.size(d);
    if (before == 0 && after == 0) continue;
    const int64_t shift = mode == "REFLECT" ? 1 : 0;
    std::vector<int64_t> index;
    for (int64_t i = -before; i < n + after; ++i) {
      int64_t j = i;
      if (j < 0) j = -j - 1 + shift;
      if (j >= n) j = 2 * n - j - 1 - shift;
      index.push_back(std::clamp<int64_t>(j, 0, n - 1));
    }
    y = y.index_select(d, torch::tensor(index, torch::kLong).to(y.device()));
  }
  return {y};
}

// Reductions over the axes of the second input.
Tensors Reduce(const GraphNode& node, const Tensors& in, const std::string& how) {
  Need(in, 2);
  const bool keep = node.Bool("keep_dims", false);
  std::vector<int64_t> axes = IntsOf(in[1]);
  for (int64_t& a : axes) a = AxisOf(a, in[0].dim());
  if (axes.empty()) return {in[0]};
  torch::Tensor x = in[0];
  if (how == "Mean") return {x.mean(axes, keep)};
  if (how == "Sum") return {x.sum(axes, keep)};
  if (how == "Prod") {
    std::sort(axes.rbegin(), axes.rend());
    for (int64_t a : axes) x = x.prod(a, keep);
    return {x};
  }
  if (how == "Max") return {x.amax(axes, keep)};
  if (how == "Min") return {x.amin(axes, keep)};
  if (how == "All" || how == "Any") {
    std::sort(axes.rbegin(), axes.rend());
    for (int64_t a : axes) x = how == "All" ? x.all(a, keep) : x.any(a, keep);
    return {x};
  }
  Fail("reduction " + how);
}

Tensors StridedSlice(const GraphNode& node, const Tensors& in) {
  Need(in, 4);
  const torch::Tensor& x = in[0];
  const std::vector<int64_t> begin = IntsOf(in[1]), end = IntsOf(in[2]), strides = IntsOf(in[3]);
  const int64_t m = static_cast<int64_t>(begin.size());
  if (static_cast<int64_t>(end.size()) != m || static_cast<int64_t>(strides.size()) != m) Fail("mismatched specs");
  const int64_t begin_mask = node.Int("begin_mask", 0), end_mask = node.Int("end_mask", 0);
  const int64_t ellipsis = node.Int("ellipsis_mask", 0), new_axis = node.Int("new_axis_mask", 0);
  const int64_t shrink = node.Int("shrink_axis_mask", 0);
  int64_t consumed = 0;  // input dimensions the spec's entries address
  for (int64_t i = 0; i < m; ++i)
    if (!((ellipsis >> i) & 1) && !((new_axis >> i) & 1)) ++consumed;
  std::vector<torch::indexing::TensorIndex> index;
  int64_t dim = 0;
  for (int64_t i = 0; i < m; ++i) {
    if ((ellipsis >> i) & 1) {
      for (int64_t k = 0; k < x.dim() - consumed; ++k, ++dim) index.emplace_back(Slice());
      continue;
    }
    if ((new_axis >> i) & 1) {
      index.emplace_back(torch::indexing::None);
      continue;
    }
    if (dim >= x.dim()) Fail("the slice has more entries than the tensor dimensions");
    const int64_t n = x.size(dim);
    if ((shrink >> i) & 1) {
      const int64_t at = begin[i] < 0 ? begin[i] + n : begin[i];
      if (at < 0 || at >= n) Fail("index out of range");
      index.emplace_back(at);
      ++dim;
      continue;
    }
    if (strides[i] <= 0) Fail("non-positive strides are not supported");
    int64_t b = (begin_mask >> i) & 1 ? 0 : begin[i] < 0 ? begin[i] + n : begin[i];
    int64_t e = (end_mask >> i) & 1 ? n : end[i] < 0 ? end[i] + n : end[i];
    b = std::clamp<int64_t>(b, 0, n);
    e = std::clamp<int64_t>(e, b, n);
    index.emplace_back(Slice(b, e, strides[i]));
    ++dim;
  }
  return {x.index(index)};
}

Tensors Split(const torch::Tensor& x, int64_t axis, const std::vector<int64_t>& sizes) {
  Tensors out;
  int64_t at = 0;
  for (int64_t s : sizes) {
    out.push_back(x.narrow(axis, at, s));
    at += s;
  }
  return out;
}

Tensors SpaceToBatch(const Tensors& in) {
  Need(in, 3);
  const std::vector<int64_t> block = IntsOf(in[1]), pads = IntsOf(in[2]);
  if (block.size() != 2 || pads.size() != 4 || in[0].dim() != 4) Fail("only 2 spatial dimensions of NHWC");
  const torch::Tensor x = F::pad(in[0], F::PadFuncOptions({0, 0, pads[2], pads[3], pads[0], pads[1]}));
  const int64_t b = x.size(0), h = x.size(1), w = x.size(2), c = x.size(3);
  if (h % block[0] || w % block[1]) Fail("padded size not divisible by the block");
  return {x.reshape({b, h / block[0], block[0], w / block[1], block[1], c})
              .permute({2, 4, 0, 1, 3, 5})
              .reshape({block[0] * block[1] * b, h / block[0], w / block[1], c})};
}

Tensors BatchToSpace(const Tensors& in) {
  Need(in, 3);
  const std::vector<int64_t> block = IntsOf(in[1]), crops = IntsOf(in[2]);
  if (block.size() != 2 || crops.size() != 4 || in[0].dim() != 4) Fail("only 2 spatial dimensions of NHWC");
  const torch::Tensor& x = in[0];
  const int64_t b = x.size(0) / (block[0] * block[1]), h = x.size(1), w = x.size(2), c = x.size(3);
  const torch::Tensor y = x.reshape({block[0], block[1], b, h, w, c})
                              .permute({2, 3, 0, 4, 1, 5})
                              .reshape({b, h * block[0], w * block[1], c});
  return {y.index({Slice(), Slice(crops[0], h * block[0] - crops[1]), Slice(crops[2], w * block[1] - crops[3])})};
}

Tensors MatMul(const GraphNode& node, const Tensors& in) {
  Need(in, 2);
  const bool ta = node.Bool("transpose_a", false) || node.Bool("adj_x", false);
  const bool tb = node.Bool("transpose_b", false) || node.Bool("adj_y", false);
  torch::Tensor y = torch::matmul(ta ? in[0].transpose(-1, -2) : in[0], tb ? in[1].transpose(-1, -2) : in[1]);
  size_t arg = 2;
  for (const std::string& op : node.Strings("fused_ops")) {
    if (op == "BiasAdd") {
      Need(in, arg + 1);
      y = y + in[arg++];
    } else if (op == "Relu") {
      y = torch::relu(y);
    } else if (op == "Relu6") {
      y = torch::clamp(y, 0.0, 6.0);
    } else if (op == "Prelu") {
      Need(in, arg + 1);
      y = Prelu(y, in[arg++]);
    } else if (op == "Sigmoid") {
      y = torch::sigmoid(y);
    } else {
      Fail("fused op " + op + " is not supported");
    }
  }
  return {y};
}

using Unary = torch::Tensor (*)(const torch::Tensor&);
using Binary = torch::Tensor (*)(const torch::Tensor&, const torch::Tensor&);

GraphOp UnaryOp(Unary f) {
  return [f](const GraphNode&, const Tensors& in) {
    Need(in, 1);
    return Tensors{f(in[0])};
  };
}
GraphOp BinaryOp(Binary f) {
  return [f](const GraphNode&, const Tensors& in) {
    Need(in, 2);
    return Tensors{f(in[0], in[1])};
  };
}

// The ops by name; each Add*Ops adds one family of them.
using OpTable = std::map<std::string, GraphOp>;

// Plumbing and dataflow control.
void AddPlumbingOps(OpTable* table) {
  OpTable& m = *table;
  m["Identity"] = [](const GraphNode&, const Tensors& in) { Need(in, 1); return Tensors{in[0]}; };
  m["StopGradient"] = m["Identity"];
  m["Snapshot"] = m["Identity"];
  m["NoOp"] = [](const GraphNode&, const Tensors&) { return Tensors{}; };
  m["Switch"] = [](const GraphNode&, const Tensors& in) {
    Need(in, 2);
    const bool pred = in[1].to(torch::kCPU).item<bool>();
    return pred ? Tensors{torch::Tensor(), in[0]} : Tensors{in[0], torch::Tensor()};
  };
  m["Merge"] = [](const GraphNode&, const Tensors& in) {
    for (size_t i = 0; i < in.size(); ++i)
      if (in[i].defined()) return Tensors{in[i], torch::tensor(int32_t(i))};
    return Tensors{};
  };
}

// Convolutions and pools.
void AddWindowOps(OpTable* table) {
  OpTable& m = *table;
  m["Conv2D"] = [](const GraphNode& n, const Tensors& in) { Need(in, 2); return Tensors{Convolve(n, in[0], in[1], false)}; };
  m["DepthwiseConv2dNative"] = [](const GraphNode& n, const Tensors& in) {
    Need(in, 2);
    return Tensors{Convolve(n, in[0], in[1], true)};
  };
  m["_FusedConv2D"] = [](const GraphNode& n, const Tensors& in) { return FusedConvolution(n, in, false); };
  m["FusedDepthwiseConv2dNative"] = [](const GraphNode& n, const Tensors& in) { return FusedConvolution(n, in, true); };
  m["Conv2DBackpropInput"] = TransposedConvolution;
  m["MaxPool"] = [](const GraphNode& n, const Tensors& in) { return Pool(n, in, true); };
  m["AvgPool"] = [](const GraphNode& n, const Tensors& in) { return Pool(n, in, false); };
  m["ResizeBilinear"] = ResizeBilinear;
  m["ResizeNearestNeighbor"] = ResizeNearest;
  m["Pad"] = [](const GraphNode& n, const Tensors& in) { return PadOp(n, in, 0.0); };
  m["PadV2"] = [](const GraphNode& n, const Tensors& in) {
    Need(in, 3);
    return PadOp(n, in, in[2].to(torch::kCPU).item<double>());
  };
  m["MirrorPad"] = [](const GraphNode& n, const Tensors& in) { return PadOp(n, in, 0.0); };
  m["SpaceToBatchND"] = [](const GraphNode&, const Tensors& in) { return SpaceToBatch(in); };
  m["BatchToSpaceND"] = [](const GraphNode&, const Tensors& in) { return BatchToSpace(in); };
  m["MatMul"] = MatMul;
  m["BatchMatMul"] = MatMul;
  m["BatchMatMulV2"] = MatMul;
  m["_FusedMatMul"] = MatMul;
}

// Element-wise.
void AddElementwiseOps(OpTable* table) {
  OpTable& m = *table;
  m["BiasAdd"] = BinaryOp([](const torch::Tensor& a, const torch::Tensor& b) { return a + b; });
  m["Add"] = m["BiasAdd"];
  m["AddV2"] = m["BiasAdd"];
  m["AddN"] = [](const GraphNode&, const Tensors& in) {
    Need(in, 1);
    torch::Tensor sum = in[0];
    for (size_t i = 1; i < in.size(); ++i) sum = sum + in[i];
    return Tensors{sum};
  };
  m["Sub"] = BinaryOp([](const torch::Tensor& a, const torch::Tensor& b) { return a - b; });
  m["Mul"] = BinaryOp([](const torch::Tensor& a, const torch::Tensor& b) { return a * b; });
  m["RealDiv"] = BinaryOp([](const torch::Tensor& a, const torch::Tensor& b) { return torch::div(a, b); });
  m["Div"] = BinaryOp([](const torch::Tensor& a, const torch::Tensor& b) {
    return a.is_floating_point() ? torch::div(a, b) : torch::div(a, b, "floor");
  });
  m["FloorDiv"] = BinaryOp([](const torch::Tensor& a, const torch::Tensor& b) { return torch::div(a, b, "floor"); });
  m["FloorMod"] = BinaryOp([](const torch::Tensor& a, const torch::Tensor& b) { return torch::remainder(a, b); });
  m["Minimum"] = BinaryOp([](const torch::Tensor& a, const torch::Tensor& b) { return torch::minimum(a, b); });
  m["Maximum"] = BinaryOp([](const torch::Tensor& a, const torch::Tensor& b) { return torch::maximum(a, b); });
  m["Pow"] = BinaryOp([](const torch::Tensor& a, const torch::Tensor& b) { return torch::pow(a, b); });
  m["SquaredDifference"] = BinaryOp([](const torch::Tensor& a, const torch::Tensor& b) { return (a - b) * (a - b); });
  m["Equal"] = BinaryOp([](const torch::Tensor& a, const torch::Tensor& b) { return torch::eq(a, b); });
  m["NotEqual"] = BinaryOp([](const torch::Tensor& a, const torch::Tensor& b) { return torch::ne(a, b); });
  m["Greater"] = BinaryOp([](const torch::Tensor& a, const torch::Tensor& b) { return torch::gt(a, b); });
  m["GreaterEqual"] = BinaryOp([](const torch::Tensor& a, const torch::Tensor& b) { return torch::ge(a, b); });
  m["Less"] = BinaryOp([](const torch::Tensor& a, const torch::Tensor& b) { return torch::lt(a, b); });
  m["LessEqual"] = BinaryOp([](const torch::Tensor& a, const torch::Tensor& b) { return torch::le(a, b); });
  m["LogicalAnd"] = BinaryOp([](const torch::Tensor& a, const torch::Tensor& b) { return torch::logical_and(a, b); });
  m["LogicalOr"] = BinaryOp([](const torch::Tensor& a, const torch::Tensor& b) { return torch::logical_or(a, b); });
  m["Prelu"] = BinaryOp(Prelu);
  m["Relu"] = UnaryOp([](const torch::Tensor& x) { return torch::relu(x); });
  m["Relu6"] = UnaryOp([](const torch::Tensor& x) { return torch::clamp(x, 0.0, 6.0); });
  m["Elu"] = UnaryOp([](const torch::Tensor& x) { return torch::elu(x); });
  m["Sigmoid"] = UnaryOp([](const torch::Tensor& x) { return torch::sigmoid(x); });
  m["Tanh"] = UnaryOp([](const torch::Tensor& x) { return torch::tanh(x); });
  m["Neg"] = UnaryOp([](const torch::Tensor& x) { return torch::neg(x); });
  m["Abs"] = UnaryOp([](const torch::Tensor& x) { return torch::abs(x); });
  m["Exp"] = UnaryOp([](const torch::Tensor& x) { return torch::exp(x); });
  m["Log"] = UnaryOp([](const torch::Tensor& x) { return torch::log(x); });
  m["Sqrt"] = UnaryOp([](const torch::Tensor& x) { return torch::sqrt(x); });
  m["Rsqrt"] = UnaryOp([](const torch::Tensor& x) { return torch::rsqrt(x); });
  m["Square"] = UnaryOp([](const torch::Tensor& x) { return x * x; });
  m["Floor"] = UnaryOp([](const torch::Tensor& x) { return torch::floor(x); });
  m["Ceil"] = UnaryOp([](const torch::Tensor& x) { return torch::ceil(x); });
  m["Sin"] = UnaryOp([](const torch::Tensor& x) { return torch::sin(x); });
  m["Cos"] = UnaryOp([](const torch::Tensor& x) { return torch::cos(x); });
  m["LogicalNot"] = UnaryOp([](const torch::Tensor& x) { return torch::logical_not(x); });
  m["ZerosLike"] = UnaryOp([](const torch::Tensor& x) { return torch::zeros_like(x); });
  m["OnesLike"] = UnaryOp([](const torch::Tensor& x) { return torch::ones_like(x); });
  m["LeakyRelu"] = [](const GraphNode& n, const Tensors& in) {
    Need(in, 1);
    return Tensors{F::leaky_relu(in[0], F::LeakyReLUFuncOptions().negative_slope(n.Float("alpha", 0.2)))};
  };
  m["Softmax"] = UnaryOp([](const torch::Tensor& x) { return torch::softmax(x, -1); });
  m["Atan2"] = BinaryOp([](const torch::Tensor& a, const torch::Tensor& b) { return torch::atan2(a, b); });
}

void AddReductionAndShapeOps(OpTable* table) {
  OpTable& m = *table;
  // Reductions.
  for (const char* r : {"Mean", "Sum", "Prod", "Max", "Min", "All", "Any"})
    m[r] = [how = std::string(r)](const GraphNode& n, const Tensors& in) { return Reduce(n, in, how); };
  // Shapes.
  m["Shape"] = [](const GraphNode& n, const Tensors& in) {
    Need(in, 1);
    const auto sizes = in[0].sizes();
    return Tensors{torch::tensor(std::vector<int64_t>(sizes.begin(), sizes.end()), torch::kLong)
                       .to(DtypeOf(n.Type("out_type", "DT_INT32")))
                       .to(in[0].device())};
  };
  m["Cast"] = [](const GraphNode& n, const Tensors& in) {
    Need(in, 1);
    return Tensors{in[0].to(DtypeOf(n.Type("DstT", "DT_FLOAT")))};
  };
  m["Reshape"] = [](const GraphNode&, const Tensors& in) { Need(in, 2); return Tensors{in[0].reshape(IntsOf(in[1]))}; };
  m["Squeeze"] = [](const GraphNode& n, const Tensors& in) {
    Need(in, 1);
    std::vector<int64_t> dims = n.Ints("squeeze_dims");
    if (dims.empty()) dims = n.Ints("axis");
    if (dims.empty()) return Tensors{in[0].squeeze()};
    for (int64_t& d : dims) d = AxisOf(d, in[0].dim());
    std::sort(dims.rbegin(), dims.rend());
    torch::Tensor y = in[0];
    for (int64_t d : dims) y = y.squeeze(d);
    return Tensors{y};
  };
  m["ExpandDims"] = [](const GraphNode&, const Tensors& in) {
    Need(in, 2);
    return Tensors{in[0].unsqueeze(AxisOf(IntsOf(in[1]).at(0), in[0].dim() + 1))};
  };
  m["ConcatV2"] = [](const GraphNode&, const Tensors& in) {
    Need(in, 2);
    const Tensors parts(in.begin(), in.end() - 1);
    return Tensors{torch::cat(parts, AxisOf(IntsOf(in.back()).at(0), parts[0].dim()))};
  };
  m["Pack"] = [](const GraphNode& n, const Tensors& in) {
    Need(in, 1);
    return Tensors{torch::stack(in, AxisOf(n.Int("axis", 0), in[0].dim() + 1))};
  };
  m["Unpack"] = [](const GraphNode& n, const Tensors& in) {
    Need(in, 1);
    const auto parts = in[0].unbind(AxisOf(n.Int("axis", 0), in[0].dim()));
    return Tensors(parts.begin(), parts.end());
  };
  m["Split"] = [](const GraphNode& n, const Tensors& in) {
    Need(in, 2);
    const int64_t axis = AxisOf(IntsOf(in[0]).at(0), in[1].dim());
    const int64_t parts = n.Int("num_split", 1);
    if (parts < 1 || in[1].size(axis) % parts) Fail("cannot split evenly");
    return Split(in[1], axis, std::vector<int64_t>(parts, in[1].size(axis) / parts));
  };
  m["SplitV"] = [](const GraphNode&, const Tensors& in) {
    Need(in, 3);
    const int64_t axis = AxisOf(IntsOf(in[2]).at(0), in[0].dim());
    std::vector<int64_t> sizes = IntsOf(in[1]);
    int64_t known = 0, unknown = -1;
    for (size_t i = 0; i < sizes.size(); ++i) {
      if (sizes[i] < 0) unknown = int64_t(i);
      else known += sizes[i];
    }
    if (unknown >= 0) sizes[unknown] = in[0].size(axis) - known;
    return Split(in[0], axis, sizes);
  };
  m["Slice"] = [](const GraphNode&, const Tensors& in) {
    Need(in, 3);
    const std::vector<int64_t> begin = IntsOf(in[1]), size = IntsOf(in[2]);
    torch::Tensor y = in[0];
    for (size_t d = 0; d < begin.size(); ++d)
      y = y.narrow(int64_t(d), begin[d], size[d] < 0 ? y.size(int64_t(d)) - begin[d] : size[d]);
    return Tensors{y};
  };
  m["StridedSlice"] = StridedSlice;
  m["BroadcastTo"] = [](const GraphNode&, const Tensors& in) { Need(in, 2); return Tensors{in[0].expand(IntsOf(in[1]))}; };
  m["Transpose"] = [](const GraphNode&, const Tensors& in) { Need(in, 2); return Tensors{in[0].permute(IntsOf(in[1]))}; };
  m["Tile"] = [](const GraphNode&, const Tensors& in) { Need(in, 2); return Tensors{in[0].repeat(IntsOf(in[1]))}; };
  m["Fill"] = [](const GraphNode&, const Tensors& in) {
    Need(in, 2);
    return Tensors{in[1].reshape({}).expand(IntsOf(in[0])).contiguous()};
  };
  m["GatherV2"] = [](const GraphNode&, const Tensors& in) {
    Need(in, 3);
    const int64_t axis = AxisOf(IntsOf(in[2]).at(0), in[0].dim());
    const torch::Tensor index = in[1].to(torch::kLong);
    const torch::Tensor flat = in[0].index_select(axis, index.reshape(-1));
    std::vector<int64_t> shape(in[0].sizes().begin(), in[0].sizes().begin() + axis);
    for (int64_t s : index.sizes()) shape.push_back(s);
    for (int64_t d = axis + 1; d < in[0].dim(); ++d) shape.push_back(in[0].size(d));
    return Tensors{flat.reshape(shape)};
  };
  m["Range"] = [](const GraphNode& n, const Tensors& in) {
    Need(in, 3);
    const auto s = in[0].to(torch::kCPU), e = in[1].to(torch::kCPU), d = in[2].to(torch::kCPU);
    return Tensors{torch::arange(s.item<double>(), e.item<double>(), d.item<double>())
                       .to(DtypeOf(n.Type("Tidx", "DT_INT32")))
                       .to(in[0].device())};
  };
}

const std::map<std::string, GraphOp>& Ops() {
  static const std::map<std::string, GraphOp> ops = [] {
    std::map<std::string, GraphOp> m;
    AddPlumbingOps(&m);
    AddWindowOps(&m);
    AddElementwiseOps(&m);
    AddReductionAndShapeOps(&m);
    return m;
  }();
  return ops;
}

}  // namespace

const GraphOp* FindGraphOp(const std::string& op) {
  const auto& ops = Ops();
  const auto it = ops.find(op);
  return it == ops.end() ? nullptr : &it->second;
}

std::vector<std::string> KnownGraphOps() {
  std::vector<std::string> names;
  for (const auto& [name, op] : Ops()) names.push_back(name);
  return names;
}

}  // namespace headforge
