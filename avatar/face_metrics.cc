#include "avatar/face_metrics.h"

#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <iterator>

#include <Eigen/Geometry>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "avatar/metrics/face_recognition.h"
#include "vision/tfjs_weights.h"
#include "capture/face_detector.h"

namespace headforge {

struct FaceMetrics::Impl {
  FaceRecognitionNet net{nullptr};
  std::unique_ptr<FaceDetector> detector;
  std::unique_ptr<LandmarkPredictor> landmarks;
};

FaceMetrics::FaceMetrics() : impl_(std::make_unique<Impl>()) {}
FaceMetrics::~FaceMetrics() = default;

Status FaceMetrics::Load(const FaceMetricsOptions& options, std::unique_ptr<FaceMetrics>* metrics) {
  std::unique_ptr<FaceMetrics> out(new FaceMetrics());
  const fs::path manifest = options.face_api_models / "face_recognition_model-weights_manifest.json";
  std::error_code ec;
  if (!fs::exists(manifest, ec))
    return Status::NotFound("face metrics: no " + manifest.string() +
                            " (scripts/install_deps.sh installs face-api with npm into .tools/node)");
  std::map<std::string, torch::Tensor> weights;
  HF_RETURN_IF_ERROR(ReadTfjsWeights(manifest, &weights));
  std::shared_ptr<FaceRecognitionNetImpl> net;
  HF_RETURN_IF_ERROR(FaceRecognitionNetImpl::Create(weights, &net));
  out->impl_->net = FaceRecognitionNet(net);
  FaceDetectorOptions detector;
  detector.ultraface_dir = options.ultraface_dir;
  HF_RETURN_IF_ERROR(FaceDetector::Create(detector, &out->impl_->detector));
  HF_RETURN_IF_ERROR(LandmarkPredictor::Load(options.landmark_model, &out->impl_->landmarks));
  *metrics = std::move(out);
  return Status::Ok();
}

bool FaceMetrics::FindFace(const cv::Mat& bgr, Face* face) {
  const std::vector<FaceDetection> faces = impl_->detector->Detect(bgr);
  if (faces.empty()) return false;
  Face found;
  found.landmark_box = faces.front().landmark_box;
  found.landmarks = LandmarksAt(bgr, found.landmark_box);
  if (!PlausibleFaceLayout(found.landmarks)) return false;
  const cv::Rect2f bounds = LandmarkBounds(found.landmarks);
  const float side = 1.2f * std::max(bounds.width, bounds.height);
  const cv::Point2f centre(bounds.x + bounds.width / 2, bounds.y + bounds.height / 2);
  found.square = cv::Rect2f(centre.x - side / 2, centre.y - side / 2, side, side);
  *face = found;
  return true;
}

Landmarks68 FaceMetrics::LandmarksAt(const cv::Mat& bgr, const cv::Rect2f& landmark_box) const {
  return impl_->landmarks->Predict(bgr, landmark_box);
}

cv::Mat FaceMetrics::Crop(const cv::Mat& bgr, const cv::Rect2f& square) {
  // Output pixel u (centre u + 0.5) from the square's point x + (u + 0.5) / s.
  const double s = 150.0 / square.width;
  const cv::Mat map =
      (cv::Mat_<double>(2, 3) << s, 0, (0.5 - square.x) * s - 0.5, 0, s, (0.5 - square.y) * s - 0.5);
  cv::Mat out;
  cv::warpAffine(bgr, out, map, cv::Size(150, 150), cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar(0, 0, 0));
  return out;
}

std::vector<std::vector<float>> FaceMetrics::Describe(const std::vector<cv::Mat>& crops) {
  std::vector<std::vector<float>> out;
  if (crops.empty()) return out;
  torch::NoGradGuard no_grad;
  std::vector<torch::Tensor> batch;
  for (const cv::Mat& crop : crops) {
    CV_Assert(crop.rows == 150 && crop.cols == 150 && crop.type() == CV_8UC3);
    cv::Mat rgb;
    cv::cvtColor(crop, rgb, cv::COLOR_BGR2RGB);
    batch.push_back(torch::from_blob(rgb.data, {150, 150, 3}, torch::kUInt8).permute({2, 0, 1}).to(torch::kFloat32));
  }
  const torch::Tensor descriptors = impl_->net->forward(torch::stack(batch)).contiguous();
  for (int64_t i = 0; i < descriptors.size(0); ++i) {
    const float* d = descriptors[i].data_ptr<float>();
    out.emplace_back(d, d + descriptors.size(1));
  }
  return out;
}

double DescriptorCosine(const std::vector<float>& a, const std::vector<float>& b) {
  double dot = 0, na = 0, nb = 0;
  for (size_t i = 0; i < a.size() && i < b.size(); ++i) {
    dot += double(a[i]) * b[i];
    na += double(a[i]) * a[i];
    nb += double(b[i]) * b[i];
  }
  return na > 0 && nb > 0 ? dot / std::sqrt(na * nb) : 0;
}

double MeanLandmarkDistance(const Landmarks68& a, const Landmarks68& b) {
  double sum = 0;
  for (size_t i = 0; i < a.size(); ++i) sum += std::hypot(double(a[i].x) - b[i].x, double(a[i].y) - b[i].y);
  return sum / double(a.size());
}

double AlignedExpressionDistance(const Landmarks68& render, const Landmarks68& frame) {
  // iBUG 68: 27-35 nose, 36/39 and 42/45 the eyes' corners; 36-47 eyes, 48-67 mouth.
  constexpr int kRigid[] = {27, 28, 29, 30, 31, 32, 33, 34, 35, 36, 39, 42, 45};
  // Dynamic sizes: GCC 12 warns falsely inside umeyama's fixed-size 2-D path.
  Eigen::MatrixXd from(2, std::size(kRigid)), to(2, std::size(kRigid));
  for (size_t i = 0; i < std::size(kRigid); ++i) {
    from.col(Eigen::Index(i)) << render[size_t(kRigid[i])].x, render[size_t(kRigid[i])].y;
    to.col(Eigen::Index(i)) << frame[size_t(kRigid[i])].x, frame[size_t(kRigid[i])].y;
  }
  const Eigen::MatrixXd frame_from_render = Eigen::umeyama(from, to, true);  // [3, 3]
  double sum = 0;
  for (size_t i = 36; i < 68; ++i) {
    const Eigen::Vector2d moved =
        frame_from_render.topLeftCorner(2, 2) * Eigen::Vector2d(render[i].x, render[i].y) +
        frame_from_render.topRightCorner(2, 1);
    sum += (moved - Eigen::Vector2d(frame[i].x, frame[i].y)).norm();
  }
  const double eyes = std::hypot(double(frame[36].x) - frame[45].x, double(frame[36].y) - frame[45].y);
  return eyes > 0 ? 100 * sum / 32 / eyes : 0;
}

FaceScore ScoreFaceInPlace(FaceMetrics& metrics, const cv::Mat& render, const cv::Mat& frame) {
  FaceScore score;
  FaceMetrics::Face face;
  score.face = metrics.FindFace(frame, &face);
  if (!score.face) return score;
  const std::vector<std::vector<float>> d =
      metrics.Describe({FaceMetrics::Crop(frame, face.square), FaceMetrics::Crop(render, face.square)});
  score.cosine = DescriptorCosine(d[0], d[1]);
  score.landmark_px = MeanLandmarkDistance(face.landmarks, metrics.LandmarksAt(render, face.landmark_box));
  return score;
}

Status ScoreHeldOutFaces(FaceMetrics& metrics, const fs::path& held_out_dir, HeldOutFaceScores* out) {
  std::vector<fs::path> strips;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(held_out_dir, ec))
    if (entry.path().extension() == ".png") strips.push_back(entry.path());
  if (ec || strips.empty()) return Status::NotFound("face metrics: no held-out views in " + held_out_dir.string());
  std::sort(strips.begin(), strips.end());
  HeldOutFaceScores result;
  for (const fs::path& strip : strips) {
    // render | frame | error, each a third of the width.
    const cv::Mat image = cv::imread(strip.string(), cv::IMREAD_COLOR);
    if (image.empty() || image.cols % 3 != 0)
      return Status::DataError("face metrics: " + strip.string() +
                               " is not a held-out strip (render | frame | error)");
    const int w = image.cols / 3;
    const cv::Mat render = image(cv::Rect(0, 0, w, image.rows)).clone();
    const cv::Mat frame = image(cv::Rect(w, 0, w, image.rows)).clone();
    result.image_size = std::max(w, image.rows);
    FaceScore score = ScoreFaceInPlace(metrics, render, frame);
    score.view = strip.stem().string();
    if (score.face) {
      result.mean_cosine += score.cosine;
      result.mean_landmark_px += score.landmark_px;
      ++result.scored;
    }
    result.per_view.push_back(score);
  }
  result.views = int(result.per_view.size());
  if (result.scored > 0) {
    result.mean_cosine /= result.scored;
    result.mean_landmark_px /= result.scored;
  }
  *out = std::move(result);
  return Status::Ok();
}

}  // namespace headforge
