#include "reconstruction/tracking_io.h"

#include <nlohmann/json.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>

#include "core/json_io.h"

namespace headforge {

const TrackedFrame* TrackingFile::Find(int index) const {
  if (index >= 0 && index < int(frames.size()) && frames[index].frame == index) return &frames[index];
  for (const TrackedFrame& f : frames)
    if (f.frame == index) return &f;
  return nullptr;
}

Status WriteTracking(const TrackingFile& t, const fs::path& path) {
  nlohmann::json frames = nlohmann::json::array();
  for (const TrackedFrame& f : t.frames) {
    if (f.expression.size() != int(t.expression_names.size()))
      return Status::Internal("tracking.json: frame " + std::to_string(f.frame) + " has " +
                              std::to_string(f.expression.size()) + " expression weights for " +
                              std::to_string(t.expression_names.size()) + " names");
    nlohmann::json weights = nlohmann::json::object();
    for (int j = 0; j < f.expression.size(); ++j) weights[t.expression_names[j]] = f.expression[j];
    frames.push_back({{"frame", f.frame},
                      {"head_motion", PoseToJson(f.head_motion)},
                      {"expression", weights},
                      {"residual_px", f.residual_px},
                      {"landmarks", f.landmarks},
                      {"interpolated", f.interpolated},
                      {"low_confidence", f.low_confidence},
                      {"why", f.why}});
  }
  const nlohmann::json json = {
      {"version", TrackingFile::kVersion},
      {"face_model", t.face_model},
      {"identity_modes", t.identity_modes},
      {"identity", std::vector<double>(t.identity.data(), t.identity.data() + t.identity.size())},
      {"expression_names", t.expression_names},
      {"head_held_by_cameras", t.head_held_by_cameras},
      {"median_residual_px", t.median_residual_px},
      {"dropped_views", t.dropped_views},
      {"landmark_embedding", t.landmark_embedding},
      {"view_dependent_landmarks", t.view_dependent_landmarks},
      {"contour_weight", t.contour_weight},
      {"solver", t.solver},
      {"seconds", t.seconds},
      {"frames", frames}};
  return WriteJsonAtomic(path, json);
}

Status ReadTracking(const fs::path& path, TrackingFile* tracking) {
  nlohmann::json j;
  HF_RETURN_IF_ERROR(ReadArtefact(path, TrackingFile::kVersion, "track", &j));
  TrackingFile t;
  try {
    t.face_model = j.at("face_model").get<std::string>();
    t.identity_modes = j.at("identity_modes").get<int>();
    const std::vector<double> identity = j.at("identity").get<std::vector<double>>();
    t.identity = Eigen::Map<const Eigen::VectorXd>(identity.data(), Eigen::Index(identity.size()));
    t.expression_names = j.at("expression_names").get<std::vector<std::string>>();
    t.head_held_by_cameras = j.at("head_held_by_cameras").get<bool>();
    t.median_residual_px = j.at("median_residual_px").get<double>();
    t.dropped_views = j.at("dropped_views").get<int>();
    t.landmark_embedding = j.at("landmark_embedding").get<std::string>();
    t.view_dependent_landmarks = j.at("view_dependent_landmarks").get<bool>();
    t.contour_weight = j.at("contour_weight").get<double>();
    t.solver = j.at("solver").get<std::string>();
    t.seconds = j.at("seconds").get<double>();
    for (const auto& f : j.at("frames")) {
      TrackedFrame frame;
      frame.frame = f.at("frame").get<int>();
      // A value that is not a number (a NaN written as null) names its frame.
      for (const auto& [name, value] : f.at("expression").items())
        if (!value.is_number())
          return Status::DataError(path.string() + ": frame " + std::to_string(frame.frame) + " has " + name + " = " +
                                   value.dump() + ", not a number; run headforge track again");
      frame.head_motion = PoseFromJson(f.at("head_motion"));
      const auto& weights = f.at("expression");
      frame.expression.resize(Eigen::Index(t.expression_names.size()));
      for (size_t k = 0; k < t.expression_names.size(); ++k)
        frame.expression[Eigen::Index(k)] = weights.at(t.expression_names[k]).get<double>();
      if (weights.size() != t.expression_names.size())
        return Status::DataError(path.string() + ": frame " + std::to_string(frame.frame) +
                                 " has weights for expressions not in expression_names; run headforge track again");
      frame.residual_px = f.at("residual_px").get<double>();
      frame.landmarks = f.at("landmarks").get<int>();
      frame.interpolated = f.at("interpolated").get<bool>();
      frame.low_confidence = f.at("low_confidence").get<bool>();
      frame.why = f.at("why").get<std::string>();
      t.frames.push_back(std::move(frame));
    }
  } catch (const nlohmann::json::exception& e) {
    return Status::DataError(path.string() + " is damaged (" + e.what() + "); run headforge track again");
  }
  *tracking = std::move(t);
  return Status::Ok();
}

Status ReadTrackedWorkspace(const fs::path& workspace, const FaceModel& model, IngestedCapture* capture,
                            CameraSet* cameras, TrackingFile* tracking) {
  HF_RETURN_IF_ERROR(ReadIngestedCapture(workspace, capture));
  HF_RETURN_IF_ERROR(CameraSet::Read(workspace / "cameras_head.json", cameras));
  HF_RETURN_IF_ERROR(ReadTracking(workspace / "tracking.json", tracking));
  const int frames = capture->num_frames();
  if (int(tracking->frames.size()) != frames)
    return Status::DataError("tracking.json holds " + std::to_string(tracking->frames.size()) +
                             " frames and the capture " + std::to_string(frames) +
                             ": the workspace's stages are out of step; run headforge track again (or headforge run)");
  if (tracking->expression_names != model.expression_names())
    return Status::DataError("tracking.json was fitted with another face model (" + tracking->face_model +
                             "); give that model with --face-model or run headforge track again");
  return Status::Ok();
}

Status ReadUndistortedFrame(const IngestedCapture& capture, const std::string& camera, const CameraIntrinsics& lens,
                            int frame, cv::Mat* image, cv::Mat* mask) {
  const fs::path image_path = capture.FramePath(camera, frame), mask_path = capture.MaskPath(camera, frame);
  *image = cv::imread(image_path.string(), cv::IMREAD_COLOR);
  *mask = cv::imread(mask_path.string(), cv::IMREAD_GRAYSCALE);
  if (image->empty()) return Status::DataError("cannot read " + image_path.string() + "; run headforge ingest again");
  if (mask->empty()) return Status::DataError("cannot read " + mask_path.string() + "; run headforge ingest again");
  if (lens.k1 != 0 || lens.k2 != 0 || lens.p1 != 0 || lens.p2 != 0) {
    const cv::Mat k = (cv::Mat_<double>(3, 3) << lens.fx, 0, lens.cx, 0, lens.fy > 0 ? lens.fy : lens.fx, lens.cy, 0, 0, 1);
    const cv::Mat dist = (cv::Mat_<double>(1, 4) << lens.k1, lens.k2, lens.p1, lens.p2);
    cv::Mat undistorted, undistorted_mask;
    cv::undistort(*image, undistorted, k, dist);
    cv::undistort(*mask, undistorted_mask, k, dist);
    *image = undistorted;
    *mask = undistorted_mask;
  }
  return Status::Ok();
}

}  // namespace headforge
