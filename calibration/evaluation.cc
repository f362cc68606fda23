#include "calibration/evaluation.h"

#include <algorithm>
#include <cmath>

#include "core/json_io.h"
#include "core/statistics.h"

namespace headforge {
namespace {

double Degrees(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  return Eigen::AngleAxisd(a.transpose() * b).angle() * 180.0 / 3.14159265358979323846;
}

struct Pair {
  Eigen::Isometry3d estimated, truth;  // cam_from_X
};

// Registered views paired with their true cam_from_world (world) or cam_from_head (head).
Status Pairs(const CameraSet& cameras, const IngestedCapture& capture, const nlohmann::json& truth, bool head,
             std::vector<Pair>* pairs, int* views, double* focal_error) {
  *views = 0;
  *focal_error = 0;
  try {
    for (const auto& cam : capture.cameras) {
      for (const auto& f : cam.frames) {
        ++*views;
        const CameraView* v = cameras.FindView(cam.name, f.index);
        if (!v || !v->registered) continue;
        const auto& frame = truth.at("frames").at(f.source_frame);
        Eigen::Isometry3d t = PoseFromJson(frame.at("views").at(cam.name).at("cam_from_world"));
        if (head) t = t * PoseFromJson(frame.at("world_from_head"));
        pairs->push_back({v->cam_from_world, t});
      }
    }
    const CameraIntrinsics* in = cameras.FindCamera(capture.cameras[0].name);
    for (const auto& c : truth.at("cameras"))
      if (in && c.at("name") == capture.cameras[0].name)
        *focal_error = std::abs(in->fx / (c.at("fx").get<double>() * capture.cameras[0].crop_scale) - 1.0);
  } catch (const nlohmann::json::exception& e) {
    return Status::DataError(std::string("ground truth does not match the capture: ") + e.what());
  }
  return Status::Ok();
}

void Summarise(const std::vector<double>& rotation, const std::vector<double>& centre, CameraErrors* e) {
  e->median_rotation_deg = Median(rotation);
  e->max_rotation_deg = rotation.empty() ? 0 : *std::max_element(rotation.begin(), rotation.end());
  e->median_centre_mm = Median(centre);
  e->max_centre_mm = centre.empty() ? 0 : *std::max_element(centre.begin(), centre.end());
}

}  // namespace

Status EvaluateWorldCameras(const CameraSet& cameras, const IngestedCapture& capture, const nlohmann::json& truth,
                            const Sim3* head_from_world, CameraErrors* errors) {
  std::vector<Pair> pairs;
  *errors = CameraErrors();
  HF_RETURN_IF_ERROR(Pairs(cameras, capture, truth, false, &pairs, &errors->views, &errors->focal_error));
  errors->registered = static_cast<int>(pairs.size());
  if (pairs.size() < 3) return Status::DataError("fewer than 3 registered views to evaluate");
  Eigen::Matrix3Xd est(3, pairs.size()), tru(3, pairs.size());
  for (size_t i = 0; i < pairs.size(); ++i) {
    est.col(i) = pairs[i].estimated.inverse().translation();
    tru.col(i) = pairs[i].truth.inverse().translation();
  }
  const SimilarityResult fit = EstimateSimilarity(est, tru);
  if (!fit.ok) return Status::DataError("cannot relate the cameras to the truth: " + fit.message);
  std::vector<double> rotation, centre;
  for (size_t i = 0; i < pairs.size(); ++i) {
    // cam_from_true_world = cam_from_world * world_from_true_world.
    const Eigen::Matrix3d r = pairs[i].estimated.linear() * fit.tgt_from_src.rotation.transpose();
    rotation.push_back(Degrees(r, pairs[i].truth.linear()));
    centre.push_back(1000.0 * (fit.tgt_from_src * est.col(i) - tru.col(i)).norm());
  }
  Summarise(rotation, centre, errors);
  if (head_from_world) errors->scale_error = std::abs(head_from_world->scale / fit.tgt_from_src.scale - 1.0);
  return Status::Ok();
}

Status EvaluateHeadCameras(const CameraSet& cameras, const IngestedCapture& capture, const nlohmann::json& truth,
                           CameraErrors* errors) {
  std::vector<Pair> pairs;
  *errors = CameraErrors();
  HF_RETURN_IF_ERROR(Pairs(cameras, capture, truth, true, &pairs, &errors->views, &errors->focal_error));
  errors->registered = static_cast<int>(pairs.size());
  std::vector<double> rotation, centre;
  for (const auto& p : pairs) {
    rotation.push_back(Degrees(p.estimated.linear(), p.truth.linear()));
    centre.push_back(1000.0 * (p.estimated.inverse().translation() - p.truth.inverse().translation()).norm());
  }
  Summarise(rotation, centre, errors);
  return Status::Ok();
}

}  // namespace headforge
