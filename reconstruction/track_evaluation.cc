#include "reconstruction/track_evaluation.h"

#include <algorithm>
#include <cmath>
#include <exception>

#include <Eigen/Geometry>

#include "core/json_io.h"
#include "core/rotation.h"
#include "core/statistics.h"

namespace headforge {

Status EvaluateTracking(const TrackingFile& tracking, const CameraSet& cameras, const IngestedCapture& capture,
                        const nlohmann::json& truth, const std::vector<std::string>& blendshapes,
                        TrackingErrors* errors) {
  TrackingErrors e;
  try {
    if (capture.cameras.empty()) return Status::DataError("the capture has no camera to score");
    const IngestedCamera& first = capture.cameras.front();
    const std::vector<TrackedFrame>& frames = tracking.frames;
    const auto& truth_frames = truth.at("frames");
    e.residual_px = tracking.median_residual_px / first.crop_scale;
    e.dropped_views = tracking.dropped_views;
    e.contour_weight = tracking.contour_weight;
    for (const std::string& name : blendshapes) {
      const auto named = std::find(tracking.expression_names.begin(), tracking.expression_names.end(), name);
      if (named == tracking.expression_names.end())
        return Status::DataError("the tracking has no blendshape named " + name);
      const Eigen::Index k = named - tracking.expression_names.begin();
      double sum = 0;
      for (const TrackedFrame& f : frames) {
        const int source = first.frames.at(size_t(f.frame)).source_frame;
        sum += std::abs(f.expression[k] - truth_frames.at(source).at("expression").at(name).get<double>());
      }
      e.mae[name] = frames.empty() ? 0.0 : sum / static_cast<double>(frames.size());
    }
    std::vector<Eigen::Matrix3d> estimated, real;
    std::vector<double> angles;
    for (const CameraView& v : cameras.views) {
      if (!v.registered) continue;
      const IngestedCamera* cam = nullptr;
      for (const IngestedCamera& c : capture.cameras)
        if (c.name == v.camera) cam = &c;
      if (!cam) return Status::DataError("cameras name a camera the capture does not have: " + v.camera);
      const int source = cam->frames.at(v.frame).source_frame;
      const TrackedFrame* tracked = tracking.Find(v.frame);
      if (!tracked) return Status::DataError("the tracking has no frame " + std::to_string(v.frame));
      const Eigen::Isometry3d motion = tracked->head_motion;
      const auto& tf = truth_frames.at(source);
      estimated.push_back(v.cam_from_world.linear() * motion.linear());
      real.push_back(
          (PoseFromJson(tf.at("views").at(cam->name).at("cam_from_world")) * PoseFromJson(tf.at("world_from_head")))
              .linear());
      angles.push_back(Eigen::AngleAxisd(estimated.back().transpose() * real.back()).angle() * 180.0 / M_PI);
    }
    if (angles.empty()) return Status::DataError("no registered views to score");
    e.views = static_cast<int>(angles.size());
    e.rotation_deg = Median(angles);
    // estimated = real · g for one constant g: the chordal mean of realᵀ estimated.
    Eigen::Matrix3d sum = Eigen::Matrix3d::Zero();
    for (size_t i = 0; i < real.size(); ++i) sum += real[i].transpose() * estimated[i];
    const Eigen::Matrix3d g = NearestRotation(sum);
    const Eigen::AngleAxisd constant(g);
    e.constant_deg = constant.axis() * constant.angle() * 180.0 / M_PI;
    std::vector<double> motion;
    for (size_t i = 0; i < real.size(); ++i)
      motion.push_back(Eigen::AngleAxisd((estimated[i] * g.transpose()).transpose() * real[i]).angle() * 180.0 / M_PI);
    e.motion_deg = Median(motion);
  } catch (const std::exception& ex) {
    return Status::DataError(std::string("the tracking does not match the capture or its truth: ") + ex.what());
  }
  *errors = e;
  return Status::Ok();
}

}  // namespace headforge
