#include "capture/face_detector.h"

#include <dlib/image_processing/frontal_face_detector.h>
#include <dlib/opencv.h>

#include <algorithm>
#include <cmath>
#include <optional>
#include <opencv2/dnn.hpp>
#include <opencv2/imgproc.hpp>

#include "core/fs.h"

namespace headforge {

Status FaceDetectorOptions::Check() const {
  if (detector != "ultraface" && detector != "ultraface-640" && detector != "dlib-hog")
    return Status::InvalidArgument("detector must be ultraface, ultraface-640 or dlib-hog, not '" +
                                   detector + "'");
  if (!(score_threshold > 0.0 && score_threshold < 1.0))
    return Status::InvalidArgument("detector threshold must be in (0, 1)");
  return Status::Ok();
}

std::string FaceDetectorOptions::UltraFaceModelPath() const {
  if (detector == "ultraface") return (fs::path(ultraface_dir) / "version-RFB-320.onnx").string();
  if (detector == "ultraface-640") return (fs::path(ultraface_dir) / "version-RFB-640.onnx").string();
  return "";
}

namespace {

class HogDetector {
 public:
  HogDetector() : detector_(dlib::get_frontal_face_detector()) {}

  std::vector<FaceDetection> Detect(const cv::Mat& bgr) {
    // HOG needs faces of at least ~80 px: upsample small images once.
    cv::Mat image = bgr;
    double scale = 1.0;
    if (std::max(bgr.cols, bgr.rows) < 640) {
      scale = 2.0;
      cv::resize(bgr, image, cv::Size(), scale, scale, cv::INTER_LINEAR);
    }
    dlib::cv_image<dlib::bgr_pixel> view(image);
    std::vector<dlib::rect_detection> found;
    detector_(view, found, 0.0);
    std::vector<FaceDetection> faces;
    for (const auto& d : found) {
      FaceDetection face;
      face.box = cv::Rect2f(d.rect.left() / scale, d.rect.top() / scale, d.rect.width() / scale,
                            d.rect.height() / scale);
      face.landmark_box = face.box;
      face.score = static_cast<float>(1.0 / (1.0 + std::exp(-d.detection_confidence)));
      face.from_fallback = true;
      faces.push_back(face);
    }
    return faces;
  }

  // dlib's own framing of the face inside `around` (a detector's box): HOG
  // run on that neighbourhood, scaled so the face is about 160 px tall.
  // The detection nearest the box's centre, if one overlaps it.
  std::optional<cv::Rect2f> FrameAround(const cv::Mat& bgr, const cv::Rect2f& around) {
    const cv::Rect2f grown(around.x - 0.5f * around.width, around.y - 0.5f * around.height, 2.0f * around.width,
                           2.0f * around.height);
    const cv::Rect region = cv::Rect(grown) & cv::Rect(0, 0, bgr.cols, bgr.rows);
    if (region.width < 16 || region.height < 16) return std::nullopt;
    const double scale = 160.0 / std::max(1.0f, around.height);
    cv::Mat crop;
    cv::resize(bgr(region), crop, cv::Size(), scale, scale, scale < 1 ? cv::INTER_AREA : cv::INTER_LINEAR);
    dlib::cv_image<dlib::bgr_pixel> view(crop);
    std::vector<dlib::rect_detection> found;
    detector_(view, found, -0.5);  // a weaker face is still framed: the box is known
    const cv::Point2f centre(around.x + 0.5f * around.width, around.y + 0.5f * around.height);
    std::optional<cv::Rect2f> best;
    float best_distance = 0;
    for (const auto& d : found) {
      const cv::Rect2f box(region.x + d.rect.left() / scale, region.y + d.rect.top() / scale, d.rect.width() / scale,
                           d.rect.height() / scale);
      const float overlap = (box & around).area() / std::min(box.area(), around.area());
      const float distance = cv::norm(cv::Point2f(box.x + 0.5f * box.width, box.y + 0.5f * box.height) - centre);
      if (overlap < 0.5f) continue;
      if (!best || distance < best_distance) {
        best = box;
        best_distance = distance;
      }
    }
    return best;
  }

 private:
  dlib::frontal_face_detector detector_;
};

// UltraFace boxes are taller than dlib's (they hold the forehead). Measured on
// 33 GRID frames of 11 clips where both detectors fired, dlib's HOG box is
// centred 0.08 box heights lower, and its side is 0.75 x the height (sd 0.06)
// or 1.15 x the width (sd 0.08); the mean of both is used.
cv::Rect2f HogFramingOf(const cv::Rect2f& ultraface) {
  const float cx = ultraface.x + 0.5f * ultraface.width;
  const float cy = ultraface.y + 0.5f * ultraface.height + 0.077f * ultraface.height;
  const float side = 0.5f * (0.75f * ultraface.height + 1.15f * ultraface.width);
  return cv::Rect2f(cx - 0.5f * side, cy - 0.5f * side, side, side);
}

// UltraFace outputs boxes already decoded to corner form, normalised to [0, 1],
// and softmax scores [background, face] for every prior.
class UltraFaceDetector : public FaceDetector {
 public:
  UltraFaceDetector(cv::dnn::Net net, cv::Size input, const FaceDetectorOptions& options)
      : net_(std::move(net)), input_(input), options_(options) {}

  std::vector<FaceDetection> Detect(const cv::Mat& bgr) override {
    cv::Mat blob = cv::dnn::blobFromImage(bgr, 1.0 / 128.0, input_, cv::Scalar(127, 127, 127),
                                          /*swapRB=*/true, /*crop=*/false);
    net_.setInput(blob);
    std::vector<cv::Mat> outputs;
    net_.forward(outputs, std::vector<cv::String>{"scores", "boxes"});
    const cv::Mat scores = outputs[0].reshape(1, outputs[0].total() / 2);
    const cv::Mat boxes = outputs[1].reshape(1, outputs[1].total() / 4);
    std::vector<cv::Rect> rects;
    std::vector<float> confidences;
    for (int i = 0; i < scores.rows; ++i) {
      const float p = scores.at<float>(i, 1);
      if (p < options_.score_threshold) continue;
      const float x0 = boxes.at<float>(i, 0) * bgr.cols, y0 = boxes.at<float>(i, 1) * bgr.rows;
      const float x1 = boxes.at<float>(i, 2) * bgr.cols, y1 = boxes.at<float>(i, 3) * bgr.rows;
      rects.emplace_back(cv::Point(cvRound(x0), cvRound(y0)), cv::Point(cvRound(x1), cvRound(y1)));
      confidences.push_back(p);
    }
    std::vector<int> keep;
    cv::dnn::NMSBoxes(rects, confidences, static_cast<float>(options_.score_threshold), 0.3f, keep);
    std::vector<FaceDetection> faces;
    for (int k : keep) {
      FaceDetection face;
      face.box = cv::Rect2f(rects[k]);
      face.landmark_box = HogFramingOf(face.box);
      face.score = confidences[k];
      faces.push_back(face);
    }
    std::sort(faces.begin(), faces.end(),
              [](const FaceDetection& a, const FaceDetection& b) { return a.score > b.score; });
    // dlib's landmark model expects its HOG detector's framing. On a turned
    // head that box follows the visible face, which a fixed conversion of
    // UltraFace's box cannot (landmarks drift by tens of pixels at 45 deg);
    // on a frontal face the conversion is as good and steadier (HOG boxes sit
    // on an 8-pixel grid). Blend by how far HOG's box moved sideways: up to 5%
    // of the width, the conversion; from 15%, HOG's box. The best few faces
    // only (ingest predicts landmarks for three).
    constexpr size_t kFramed = 3;
    for (size_t i = 0; options_.hog_framing && i < std::min(faces.size(), kFramed); ++i) {
      const cv::Rect2f a = faces[i].landmark_box;
      const std::optional<cv::Rect2f> framed = hog_.FrameAround(bgr, faces[i].box);
      if (!framed || framed->width < 0.5f * a.width || framed->width > 2.0f * a.width) continue;
      const float shift = std::abs((framed->x + 0.5f * framed->width) - (a.x + 0.5f * a.width)) / a.width;
      const float w = std::clamp((shift - 0.05f) / 0.10f, 0.0f, 1.0f);
      faces[i].landmark_box = cv::Rect2f(a.x + w * (framed->x - a.x), a.y + w * (framed->y - a.y),
                                         a.width + w * (framed->width - a.width), a.height + w * (framed->height - a.height));
    }
    if (faces.empty() && options_.hog_fallback) faces = hog_.Detect(bgr);
    return faces;
  }

 private:
  cv::dnn::Net net_;
  cv::Size input_;
  FaceDetectorOptions options_;
  HogDetector hog_;
};

class HogOnlyDetector : public FaceDetector {
 public:
  std::vector<FaceDetection> Detect(const cv::Mat& bgr) override {
    auto faces = hog_.Detect(bgr);
    for (auto& f : faces) f.from_fallback = false;
    std::sort(faces.begin(), faces.end(),
              [](const FaceDetection& a, const FaceDetection& b) { return a.score > b.score; });
    return faces;
  }

 private:
  HogDetector hog_;
};

}  // namespace

Status FaceDetector::Create(const FaceDetectorOptions& options,
                            std::unique_ptr<FaceDetector>* detector) {
  HF_RETURN_IF_ERROR(options.Check());
  if (options.detector == "dlib-hog") {
    *detector = std::make_unique<HogOnlyDetector>();
    return Status::Ok();
  }
  const std::string path = options.UltraFaceModelPath();
  if (Status readable = CheckReadableFile(path, "UltraFace model"); !readable.ok()) {
    if (readable.code() != Status::Code::kNotFound) return readable;
    return Status::NotFound(readable.message() +
                            " (it is in the shared data folder: give --data DIR, or --detector dlib-hog to detect "
                            "faces without it)");
  }
  cv::dnn::Net net;
  try {
    net = cv::dnn::readNetFromONNX(path);
  } catch (const cv::Exception& e) {
    return Status::DataError("cannot load the UltraFace model " + path + ": " + e.what());
  }
  if (net.empty()) return Status::DataError("cannot load the UltraFace model " + path);
  net.setPreferableBackend(cv::dnn::DNN_BACKEND_OPENCV);
  net.setPreferableTarget(cv::dnn::DNN_TARGET_CPU);
  const cv::Size input = options.detector == "ultraface" ? cv::Size(320, 240) : cv::Size(640, 480);
  *detector = std::make_unique<UltraFaceDetector>(std::move(net), input, options);
  return Status::Ok();
}

}  // namespace headforge
