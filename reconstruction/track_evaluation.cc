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
      const IngestedCamera* cam = capture.FindCamera(v.camera);
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

Status TruthAsTracked(const IngestedCapture& capture, const nlohmann::json& truth,
                      const std::set<std::string>& parts, CameraSet* cameras, TrackingFile* tracking) {
  for (const std::string& part : parts)
    if (part != "cameras" && part != "expression" && part != "identity")
      return Status::InvalidArgument("no part '" + part + "' of the truth (cameras, expression, identity)");
  if (parts.empty()) return Status::InvalidArgument("no part of the truth named (cameras, expression, identity)");
  CameraSet set = *cameras;
  TrackingFile t = *tracking;
  try {
    const auto& truth_frames = truth.at("frames");
    // Output frame -> the simulator's frame it came from (the first camera's
    // sampling: every camera of a simulated capture is sampled alike).
    auto source_of = [&](const IngestedCamera& cam, int frame) { return cam.frames.at(size_t(frame)).source_frame; };
    if (parts.count("identity")) {
      const std::vector<double> alpha = truth.at("identity").get<std::vector<double>>();
      t.identity = Eigen::VectorXd::Zero(std::max<Eigen::Index>(t.identity.size(), Eigen::Index(alpha.size())));
      for (size_t i = 0; i < alpha.size(); ++i) t.identity[Eigen::Index(i)] = alpha[i];
      t.identity_modes = int(t.identity.size());
    }
    if (parts.count("expression")) {
      if (capture.cameras.empty()) return Status::DataError("the capture has no camera");
      const IngestedCamera& first = capture.cameras.front();
      for (TrackedFrame& f : t.frames) {
        const auto& weights = truth_frames.at(source_of(first, f.frame)).at("expression");
        for (size_t k = 0; k < t.expression_names.size(); ++k)
          f.expression[Eigen::Index(k)] = weights.at(t.expression_names[k]).get<double>();
      }
    }
    if (parts.count("cameras")) {
      const bool head_pose = set.mode == "head-pose";
      const Eigen::Isometry3d world_from_first = PoseFromJson(truth_frames.at(0).at("world_from_head"));
      std::vector<CameraView> views;
      for (const IngestedCamera& cam : capture.cameras) {
        if (!cam.fixed_crop)
          return Status::InvalidArgument("camera " + cam.name + " was ingested with a crop per frame; the truth's "
                                         "cameras need one crop per camera (ingest --crop sequence)");
        const nlohmann::json* lens = nullptr;
        for (const auto& c : truth.at("cameras"))
          if (c.at("name").get<std::string>() == cam.name) lens = &c;
        if (!lens) return Status::DataError("the truth has no camera " + cam.name);
        CameraIntrinsics* intrinsics = nullptr;
        for (CameraIntrinsics& c : set.cameras)
          if (c.name == cam.name) intrinsics = &c;
        if (!intrinsics) return Status::DataError("the cameras have no camera " + cam.name);
        // Source pixels to frame pixels: u_frame = (u_src + 0.5 - x0) * scale - 0.5.
        const double s = cam.crop_scale;
        intrinsics->fx = lens->at("fx").get<double>() * s;
        intrinsics->fy = lens->at("fy").get<double>() * s;
        intrinsics->cx = (lens->at("cx").get<double>() + 0.5 - cam.crop_x0) * s - 0.5;
        intrinsics->cy = (lens->at("cy").get<double>() + 0.5 - cam.crop_y0) * s - 0.5;
        // Radial distortion acts on normalised coordinates, which the crop
        // leaves as they were.
        intrinsics->k1 = lens->value("k1", 0.0);
        intrinsics->k2 = lens->value("k2", 0.0);
        intrinsics->p1 = intrinsics->p2 = 0;
        intrinsics->model = intrinsics->k1 != 0 || intrinsics->k2 != 0 ? "OPENCV" : "PINHOLE";
        for (const IngestedFrame& f : cam.frames) {
          const auto& tf = truth_frames.at(source_of(cam, f.index));
          const Eigen::Isometry3d cam_from_world = PoseFromJson(tf.at("views").at(cam.name).at("cam_from_world"));
          const Eigen::Isometry3d world_from_head = PoseFromJson(tf.at("world_from_head"));
          CameraView v;
          v.camera = cam.name;
          v.frame = f.index;
          v.registered = true;
          // Head-pose cameras carry the head's motion themselves; other
          // modes keep the frame-0 head frame as the world and move the head.
          v.cam_from_world = head_pose ? cam_from_world * world_from_head : cam_from_world * world_from_first;
          views.push_back(v);
        }
      }
      set.views = std::move(views);
      set.notes = "the simulator's cameras (" + truth.value("scene", std::string("scene")) + "'s ground_truth.json)";
      const IngestedCamera& first = capture.cameras.front();
      for (TrackedFrame& f : t.frames) {
        const Eigen::Isometry3d world_from_head = PoseFromJson(truth_frames.at(source_of(first, f.frame)).at("world_from_head"));
        f.head_motion = head_pose ? Eigen::Isometry3d::Identity() : world_from_first.inverse() * world_from_head;
      }
    }
    for (TrackedFrame& f : t.frames) {
      if (!parts.count("cameras") || !parts.count("expression")) continue;
      f.interpolated = f.low_confidence = false;
      f.why.clear();
    }
  } catch (const std::exception& ex) {
    return Status::DataError(std::string("the truth does not match the capture: ") + ex.what());
  }
  *cameras = std::move(set);
  *tracking = std::move(t);
  return Status::Ok();
}

}  // namespace headforge
