// Face metrics of a render against the frame it should match, beside PSNR
// and SSIM:
// - Identity (CSIM): the cosine of the two faces' descriptors by a
//   face-recognition network, 1 for the same face. The network is
//   face-api's (npm's @vladmandic/face-api, MIT, weights in the package),
//   run in LibTorch (avatar/metrics/face_recognition.h), on crops made as
//   face-api makes them. Papers' CSIM uses ArcFace, whose weights cannot be
//   had here: these figures are this network's, not comparable with theirs.
//   On GRID's clips (face_metrics_test): two frames of one speaker about
//   0.99, one man in two clips 0.98, two speakers 0.80-0.92.
// - Landmark distance (F-LMD): the mean distance between the 68 landmarks
//   ingest's landmark model finds on the frame and on the render, in pixels
//   of the image scored.
// The face is found in the frame by ingest's detector; the render is
// cropped, and its landmarks predicted, from the same place, so a render
// out of place scores worse too. Torch-free.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "capture/landmarks.h"
#include "core/fs.h"
#include "core/status.h"

namespace headforge {

struct FaceMetricsOptions {
  fs::path face_api_models;    // face-api's model/ folder (face_recognition_model-weights_manifest.json)
  std::string landmark_model;  // dlib's 68-point model
  std::string ultraface_dir;   // the face detector's ONNX files
};

class FaceMetrics {
 public:
  static Status Load(const FaceMetricsOptions& options, std::unique_ptr<FaceMetrics>* metrics);
  ~FaceMetrics();

  struct Face {
    cv::Rect2f landmark_box;  // where the landmark model looks (the detector's, in its framing)
    Landmarks68 landmarks;
    // The square the recognition network's crop covers: the landmarks'
    // bounds grown by a tenth of their width and height on each side
    // (face-api's alignment box), squared about its centre.
    cv::Rect2f square;
  };
  // The most confident face in a BGR image; false when there is none.
  bool FindFace(const cv::Mat& bgr, Face* face);
  // The 68 landmarks of whatever is at `landmark_box`.
  Landmarks68 LandmarksAt(const cv::Mat& bgr, const cv::Rect2f& landmark_box) const;
  // `square` of the image at 150x150 (zero outside the image), BGR.
  static cv::Mat Crop(const cv::Mat& bgr, const cv::Rect2f& square);
  // 150x150 BGR crops -> 128-d descriptors.
  std::vector<std::vector<float>> Describe(const std::vector<cv::Mat>& crops);

 private:
  FaceMetrics();
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

double DescriptorCosine(const std::vector<float>& a, const std::vector<float>& b);
// The mean distance between corresponding points.
double MeanLandmarkDistance(const Landmarks68& a, const Landmarks68& b);

// F-LMD of the expression alone, for a render that does not sit where its
// frame's face does (another person drives it, or its camera is another):
// `render`'s landmarks moved onto `frame`'s by the similarity (Umeyama
// 1991) that best fits their rigid points (nose and eye corners), then the
// mean distance over the eyes' and the mouth's 32 points, in units of the
// frame's outer-eye-corner distance (x 100: percent of it). Pose, position
// and size of the face leave it; the shapes of eyes and mouth stay, so two
// people making the same expression do not score 0.
double AlignedExpressionDistance(const Landmarks68& render, const Landmarks68& frame);

struct FaceScore {
  std::string view;
  bool face = false;         // a face was found in the frame; the scores are set when it was
  double cosine = 0;         // CSIM, render against frame
  double landmark_px = 0;    // F-LMD, pixels
};

// `render` against `frame`, both cropped at the frame's face (ScoreHeldOutFaces' score).
FaceScore ScoreFaceInPlace(FaceMetrics& metrics, const cv::Mat& render, const cv::Mat& frame);

struct HeldOutFaceScores {
  int views = 0, scored = 0;  // held-out views, and those whose frame shows a face
  int image_size = 0;         // the scored images' longer side, pixels (F-LMD's unit)
  double mean_cosine = 0, mean_landmark_px = 0;  // over the scored views
  std::vector<FaceScore> per_view;
};

// The held-out views a trained model left in `held_out_dir` (render | frame |
// error strips, as training writes them): each render against its frame.
Status ScoreHeldOutFaces(FaceMetrics& metrics, const fs::path& held_out_dir, HeldOutFaceScores* out);

}  // namespace headforge
