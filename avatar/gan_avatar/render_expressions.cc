// The expressions of images read by the landmark model and tracker (render_expressions.h).
#include "avatar/gan_avatar/render_expressions.h"

#include <torch/torch.h>

#include <opencv2/imgproc.hpp>

#include <algorithm>

#include "avatar/train/tensor_image.h"
#include "avatar/train/view_camera.h"
#include "calibration/landmark_embedding.h"
#include "capture/landmarks.h"
#include "core/interrupt.h"
#include "core/log.h"
#include "reconstruction/landmark_basis.h"
#include "reconstruction/tracker.h"

namespace headforge {

namespace {

// The box dlib's landmark model expects (its HOG detector's framing: square,
// from the brows to about the chin) round where `points` (the 68 landmarks,
// pixels) are.
cv::Rect2f LandmarkModelBox(const std::array<Eigen::Vector2d, 68>& points) {
  double x0 = 1e9, x1 = -1e9, y0 = 1e9;
  for (int i = ibug::kJawFirst; i <= ibug::kJawLast; ++i) {
    x0 = std::min(x0, points[size_t(i)].x());
    x1 = std::max(x1, points[size_t(i)].x());
  }
  for (int i = ibug::kBrowFirst; i <= ibug::kBrowLast; ++i) y0 = std::min(y0, points[size_t(i)].y());
  const double y1 = points[ibug::kChin].y();
  const double side = std::max(x1 - x0, y1 - y0);
  const double cx = 0.5 * (x0 + x1), cy = 0.5 * (y0 + y1);
  return cv::Rect2f(float(cx - side / 2), float(cy - side / 2), float(side), float(side));
}

}  // namespace

Status EstimateImageExpressions(const at::Tensor& images, const std::vector<SplatCamera>& cameras,
                                const FaceModel& model, const TrackingFile& tracking,
                                const RenderExpressionOptions& options, Progress* progress, RenderExpressions* out) {
  const int samples = int(images.size(0)), width = int(images.size(3)), height = int(images.size(2));
  if (cameras.empty() || (cameras.size() != 1 && int(cameras.size()) != samples))
    return Status::InvalidArgument("reading expressions: one camera, or one per image, is needed");
  std::unique_ptr<LandmarkPredictor> predictor;
  HF_RETURN_IF_ERROR(LandmarkPredictor::Load(options.landmark_model, &predictor));
  const std::string embedding =
      tracking.landmark_embedding.empty() ? DefaultLandmarkEmbedding() : tracking.landmark_embedding;
  LandmarkBasis basis;
  HF_RETURN_IF_ERROR(
      BuildLandmarkBasis(model, LoadLandmarkEmbedding(model, embedding), tracking.identity_modes, &basis));
  // Each camera at the landmark image's size, for the tracker and for the
  // landmark model's box (where the subject's neutral face projects).
  const double scale = double(options.landmark_size) / std::max(width, height);
  const int big_w = int(std::lround(width * scale)), big_h = int(std::lround(height * scale));
  const Eigen::VectorXd neutral = Eigen::VectorXd::Zero(basis.num_expressions);
  std::vector<TrackingCamera> lenses;
  std::vector<cv::Rect2f> boxes;
  for (const SplatCamera& camera : cameras) {
    const SplatCamera big = camera.Downscaled(double(camera.width) / big_w);
    TrackingCamera tc;
    tc.fx = big.fx;
    tc.fy = big.fy;
    tc.cx = big.cx;
    tc.cy = big.cy;
    const Eigen::Isometry3d cam_from_head = CameraPose(big);
    tc.rotation = cam_from_head.linear();
    tc.translation = cam_from_head.translation();
    std::array<Eigen::Vector2d, 68> projected;
    for (int i = 0; i < 68; ++i) projected[size_t(i)] = tc.Pixel(basis.Point(i, tracking.identity, neutral));
    lenses.push_back(tc);
    boxes.push_back(LandmarkModelBox(projected));
  }

  const torch::Tensor cpu = images.detach().clamp(0, 1).cpu();
  std::vector<TrackingView> views;
  progress->Start("train: gan-avatar reading expressions", samples);
  for (int k = 0; k < samples; ++k) {
    cv::Mat bgr;
    cv::resize(TensorToImage(cpu[k]), bgr, cv::Size(big_w, big_h), 0, 0, cv::INTER_CUBIC);
    const size_t c = cameras.size() == 1 ? 0 : size_t(k);
    const Landmarks68 points = predictor->Predict(bgr, boxes[c]);
    TrackingView view;
    view.frame = k;
    view.camera = lenses[c];
    std::array<Eigen::Vector2d, 68> found;
    for (int i = 0; i < 68; ++i) found[size_t(i)] = {points[size_t(i)].x, points[size_t(i)].y};
    view.landmarks = found;
    views.push_back(view);
    progress->Advance();
    if (InterruptRequested()) {
      progress->Finish("interrupted");
      return Status::Interrupted("train: stopped while reading expressions for the expression mapping; the GAN is "
                                 "kept: run the same command again to go on from it");
    }
  }
  progress->Finish(std::to_string(samples) + " images");
  // Every image one frame: its camera carries the (fixed) head, the
  // identity is shared, nothing ties one image to the next.
  TrackOptions fit;
  fit.identity_modes = tracking.identity_modes;
  fit.fixed_head = true;
  fit.rotation_smoothness = fit.translation_smoothness = fit.expression_smoothness = 0;
  fit.threads = options.threads;
  TrackResult result;
  HF_RETURN_IF_ERROR(TrackSequence(basis, views, samples, fit, &result).WithContext("tracking the images"));
  // Images the tracker flagged (a large residual: one the landmark model
  // reads poorly) are kept and counted: the mapping learns from them what
  // the tracker can say. Only images without a fit are left out.
  std::vector<int64_t> kept;
  std::vector<torch::Tensor> expressions;
  int flagged = 0;
  for (const TrackedFrame& f : result.frames) {
    if (f.interpolated) continue;
    flagged += f.low_confidence ? 1 : 0;
    kept.push_back(f.frame);
    expressions.push_back(torch::from_blob(const_cast<double*>(f.expression.data()), {f.expression.size()},
                                           torch::kFloat64)
                              .to(torch::kFloat32)
                              .clone());
  }
  out->rendered = samples;
  out->median_residual_px = result.median_residual_px;
  if (kept.empty())
    return Status::DataError("the tracker fitted none of the " + std::to_string(samples) +
                             " images (median landmark residual " + std::to_string(result.median_residual_px) +
                             " px); for the GAN's renders, train the GAN longer (--steps, --max-minutes) or at a "
                             "larger --train-size");
  out->index = torch::tensor(kept, torch::kLong);
  out->images = cpu.index_select(0, out->index);
  out->expressions = torch::stack(expressions);
  out->flagged = flagged;
  HF_LOG(Info) << "train: gan-avatar: " << kept.size() << " of " << samples << " images tracked, " << flagged
               << " of them flagged (median landmark residual " << result.median_residual_px << " px at " << big_w
               << "x" << big_h << ")";
  return Status::Ok();
}

}  // namespace headforge
