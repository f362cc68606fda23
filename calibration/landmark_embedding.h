// Where the landmark detector's 68 points sit on the face model. Detectors
// follow their training annotations, which differ from the model's landmark
// vertices by millimetres (brows lower, eye corners inward, ...), enough to
// bias head poses by degrees. The embedding is measured once on simulator
// renders of the mean face under light, over a sweep of head rotations: each
// detected point is carried back to the head frame through the render's depth
// and the known pose, and the points are averaged. A second measurement over
// a wider sweep keeps the points apart by the camera's direction (a grid of
// yaw and pitch), for fits whose views see the head from far apart.
#pragma once

#include <Eigen/Geometry>
#include <functional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "capture/face_detector.h"
#include "core/face_model.h"
#include "core/hash.h"
#include "core/status.h"

namespace headforge {

// 68 head-frame points (metres); landmarks never seen keep the model's vertex.
Status MeasureLandmarkEmbedding(const FaceModel& model, const FaceDetectorOptions& detector,
                                const std::string& landmark_model, int threads, std::vector<Eigen::Vector3d>* points);

Status WriteLandmarkEmbedding(const std::string& path, const std::vector<Eigen::Vector3d>& points);
Status ReadLandmarkEmbedding(const std::string& path, std::vector<Eigen::Vector3d>* points);

// The points as the detector places them from each direction of the camera:
// from the side the jaw contour follows the silhouette and the inner points
// shift too. Nodes on a grid of the camera's direction seen from the head
// (yaw about the head's up axis, pitch up; degrees), blended bilinearly and
// clamped at the grid's edges.
struct LandmarkEmbedding {
  std::vector<Eigen::Vector3d> points;  // 68, over every direction
  std::vector<double> yaw_deg, pitch_deg;  // ascending; empty: no view dependence
  std::vector<std::vector<Eigen::Vector3d>> nodes;  // [pitch * yaw_deg.size() + yaw] -> 68 points
  // How each point moves with the face model's first identity coefficients:
  // 68 blocks [3, K] (metres per standard deviation), measured over many
  // subjects; `points` then hold the points at alpha = 0. Empty: the points
  // move with the surface they are attached to.
  std::vector<Eigen::Matrix<double, 3, Eigen::Dynamic>> identity;

  bool view_dependent() const { return !nodes.empty(); }
  // (node, weight) pairs summing to 1 for a direction from the head's origin
  // toward the camera, in the head frame; none without grid angles.
  std::vector<std::pair<int, double>> NodeWeights(const Eigen::Vector3d& toward_camera) const;
};
Status ReadLandmarkEmbedding(const std::string& path, LandmarkEmbedding* embedding);
Status WriteLandmarkEmbedding(const std::string& path, const LandmarkEmbedding& embedding);
// MeasureLandmarkEmbedding's points, and a grid of yaw -60..60 and pitch
// -20..20 degrees (10 apart) measured as the mean face turns +-65 degrees and
// nods +-22 before the camera. `only_nodes` (indices into `nodes`; empty:
// all) measures those nodes alone: the renders none of them draws on are
// skipped and the other nodes keep the points over every direction.
Status MeasureViewLandmarkEmbedding(const FaceModel& model, const FaceDetectorOptions& detector,
                                    const std::string& landmark_model, int threads, LandmarkEmbedding* embedding,
                                    const std::vector<int>& only_nodes = {});
// One subject's sweep: the face model with identity `alpha`, skin colour
// `skin` and a light from `light` (head frame, toward the light) turns +-25
// degrees and nods +-12 over 60 renders. `points` gets each landmark's mean
// head-frame point and `seen` how many renders it was found on (0: the
// point is undefined).
struct SubjectLook {
  Eigen::VectorXd alpha;
  Eigen::Vector3d skin{0.78, 0.58, 0.47};
  Eigen::Vector3d light{0.4, 0.5, 0.9};
  double ambient = 0.45, diffuse = 0.7;
};
Status MeasureSubjectLandmarks(const FaceModel& model, const FaceDetectorOptions& detector,
                               const std::string& landmark_model, int threads, const SubjectLook& look,
                               std::vector<Eigen::Vector3d>* points, std::vector<int>* seen);

// The measurements' renders: a scene of one subject under one light, the
// camera 0.65 m in front, the head turning and nodding by these amplitudes
// (degrees) over `frames` frames.
std::string EmbeddingScene(int frames, double yaw, double yaw_period, double pitch, double pitch_period,
                           const SubjectLook& look = SubjectLook());
// A detector's points on a render (BGR), in pixels; none where it found no face.
using RenderPointDetector = std::function<std::vector<cv::Point2f>(const cv::Mat& bgr)>;
// A found point: its index, its head-frame position (metres) and the
// camera's centre in the head frame.
using RenderedPointUse = std::function<void(int, const Eigen::Vector3d&, const Eigen::Vector3d&)>;
// Whether a render from this camera centre (head frame) is wanted.
using RenderedDirectionFilter = std::function<bool(const Eigen::Vector3d&)>;
// Renders `scene_text` (the face model) and hands every point `detect` finds
// that lands on the head to `use`, carried to the head frame through the
// render's depth and its known pose. Frames `want` refuses are not rendered.
Status ForEachRenderedPoint(const std::string& scene_text, const FaceModel& model, int threads,
                            const RenderPointDetector& detect, const RenderedPointUse& use,
                            const RenderedDirectionFilter& want = nullptr);

// The embedding file when it exists and loads, else the model's landmark vertices.
LandmarkEmbedding LoadLandmarkEmbedding(const FaceModel& model, const std::string& embedding_path);

// The 68 points a solver should use: the embedding file when it exists and
// loads, else the model's landmark vertices.
std::vector<Eigen::Vector3d> DetectorLandmarkPoints(const FaceModel& model, const std::string& embedding_path);

// The embedding shipped in data/ (for the ICT model and dlib's 68-point predictor).
std::string DefaultLandmarkEmbedding();
// The same with the view grid (embed-landmarks --views), for `track`.
std::string ViewLandmarkEmbedding();
// The points with their identity columns (embed-landmarks --identity), for `track`.
std::string IdentityLandmarkEmbedding();

// Adds what each embedding file holds to a stage's fingerprint (its contents,
// not its path: the shipped files move with the program); "" stands for the
// face model's own landmark vertices.
Status AddLandmarkEmbeddingInputs(const std::vector<std::string>& files, Hasher* hasher);

}  // namespace headforge
