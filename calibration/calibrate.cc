#include "calibration/calibrate.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <sstream>
#include <nlohmann/json.hpp>

#include "calibration/landmark_embedding.h"
#include "core/json_io.h"
#include "core/log.h"
#include "core/paths.h"

namespace headforge {

Status CalibrateOptions::Check() const {
  if (mode != "auto" && mode != "colmap" && mode != "head-pose" && mode != "rig")
    return Status::InvalidArgument("--mode must be auto, colmap, head-pose or rig, not '" + mode + "'");
  if (mode == "rig" && rig.empty()) return Status::InvalidArgument("--mode rig needs --rig FILE");
  if (min_registered < 0 || min_registered > 1) return Status::InvalidArgument("--min-registered must be in [0, 1]");
  if (static_rig != "auto" && static_rig != "yes" && static_rig != "no")
    return Status::InvalidArgument("--static-rig must be auto, yes or no");
  HF_RETURN_IF_ERROR(colmap.Check());
  return head_pose.Check();
}

void AddCalibrateOptions(OptionSet* o, CalibrateOptions* c) {
  o->Add("calibrate.mode", &c->mode,
         "auto, colmap, head-pose or rig. auto: head-pose for one video with a still background, "
         "else colmap (falling back to head-pose when COLMAP registers too few frames).",
         "mode");
  o->Add("calibrate.rig", &c->rig, "Rig file for --mode rig: JSON (docs/calibration.md) or a COLMAP text model folder.",
         "rig");
  o->Add("calibrate.min_registered", &c->min_registered,
         "Fewest frames COLMAP must register, as a fraction of those it was given.", "min-registered");
  o->Add("calibrate.motion_threshold", &c->motion_threshold_px,
         "Median background motion (px) above which one video counts as a moving camera.", "motion-threshold");
  o->Add("calibrate.landmark_embedding", &c->landmark_embedding,
         "Where the detector's 68 landmarks sit on the face model (headforge embed-landmarks); "
         "empty: the model's landmark vertices.",
         "landmark-embedding", OptionSet::Effect::kRuntime);  // its contents count instead (the job's inputs)
  c->colmap.executable = DefaultColmapExecutable();
  o->Add("calibrate.colmap.executable", &c->colmap.executable, "The colmap program.", "colmap",
         OptionSet::Effect::kRuntime);
  o->Add("calibrate.colmap.camera_model", &c->colmap.camera_model,
         "COLMAP camera model: SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL or OPENCV.", "camera-model");
  o->Add("calibrate.colmap.max_features", &c->colmap.max_features, "SIFT features per image.", "max-features");
  o->Add("calibrate.colmap.matcher", &c->colmap.matcher,
         "auto (sequential for one video, exhaustive for several), sequential or exhaustive.", "matcher");
  o->Add("calibrate.colmap.overlap", &c->colmap.overlap, "Sequential matcher: neighbours per image.", "overlap");
  o->Add("calibrate.colmap.mask", &c->colmap.mask,
         "Pixels COLMAP may use: auto, none, background (not the head) or head.", "colmap-mask");
  o->Add("calibrate.colmap.frame_step", &c->colmap.frame_step, "Give COLMAP every n-th frame.", "frame-step");
  o->Add("calibrate.colmap.exhaustive_fallback_max", &c->colmap.exhaustive_fallback_max,
         "When sequential matching leaves over 10% of the frames unregistered, match every pair and map again, "
         "for up to this many frames (0: never).",
         "exhaustive-fallback");
  o->Add("calibrate.colmap.keyframe_step", &c->colmap.keyframe_step,
         "When sequential matching leaves over 10% of the frames unregistered (frames a few degrees apart, e.g. "
         "every frame of a walk round a head), map one image in this many (then in twice as many) and register "
         "the rest into that model, before matching every pair (0: never).",
         "keyframe-step");
  o->Add("calibrate.colmap.revisit_angle_deg", &c->colmap.revisit_angle_deg,
         "One video: after a first model, also match images it shows looking at the same part of the scene from "
         "within this angle (degrees) but further apart in time than --overlap (the camera came back, e.g. "
         "round the head), and refine the model with those matches; closes the loop. 0: off.",
         "revisit-angle");
  o->Add("calibrate.colmap.revisit_pairs", &c->colmap.revisit_pairs,
         "Most revisit pairs per image (--revisit-angle), the nearest in direction first.", "revisit-pairs");
  o->Add("calibrate.static_rig", &c->static_rig,
         "Several cameras: auto (fixed when no camera's background moves), yes or no. Fixed cameras are "
         "calibrated from synchronised frames and keep one pose each.",
         "static-rig");
  o->Add("calibrate.colmap.rig_instants", &c->colmap.rig_instants,
         "Fixed cameras: synchronised instants given to COLMAP.", "rig-instants");
  o->Add("calibrate.colmap.max_instant_rotation_deg", &c->colmap.max_instant_rotation_deg,
         "Fixed cameras at several instants: fail when COLMAP turns one camera by more than this between its "
         "instants (degrees).",
         "max-instant-rotation");
  o->Add("calibrate.colmap.max_instant_shift", &c->colmap.max_instant_shift,
         "Fixed cameras at several instants: fail when COLMAP moves one camera by more than this fraction of the "
         "rig's size between its instants.",
         "max-instant-shift");
  o->Add("calibrate.head_pose.focal", &c->head_pose.focal,
         "Head-pose mode: focal length in frame pixels (the ingested frames'); 0 estimates it.", "focal");
  o->Add("calibrate.head_pose.fov", &c->head_pose.fov_deg,
         "Head-pose mode: the source video's horizontal field of view in degrees, for a known lens (a phone's main "
         "camera about 65-70, a webcam 60-80); sets the focal length instead of estimating it (0: estimate).",
         "fov");
  o->Add("calibrate.head_pose.prior_fov", &c->head_pose.prior_fov_deg,
         "Head-pose mode: an estimated focal length is held toward a lens of this horizontal field of view "
         "(degrees, over the source video) where the landmarks leave it undetermined (a head that barely turns).",
         "focal-prior-fov");
  o->Add("calibrate.head_pose.prior_sigma", &c->head_pose.prior_sigma,
         "Head-pose mode: the spread of that prior in log units (0.7: a factor of 2 either way); 0: no prior.",
         "focal-prior-sigma");
  o->Add("calibrate.head_pose.smoothness", &c->head_pose.smoothness,
         "Head-pose mode: weight of temporal smoothness (0: none).", "smoothness");
  o->Add("calibrate.head_pose.robust_px", &c->head_pose.robust_px,
         "Head-pose mode: Huber scale of landmark residuals (px).", "robust-px");
  o->Add("calibrate.head_pose.refine", &c->head_pose.refine,
         "Head-pose mode: face-model refines the focal length and poses by fitting the face model's identity and "
         "expressions too (with --focal or --fov, the poses alone at that focal length); off keeps the fit to the mean "
         "face's landmarks.",
         "head-pose-refine");
  o->Add("calibrate.head_pose.refine_rounds", &c->head_pose.refine_rounds,
         "Head-pose mode: face-model fits at most, each started from the cameras the last one left, until the "
         "focal length changes by less than 1%.",
         "head-pose-refine-rounds");
  o->Add("calibrate.head_pose.features", &c->head_pose.features,
         "Head-pose mode, after the face-model refinement: SIFT features on the head's rigid part (nose, upper cheeks, "
         "brows), tracked over the frames and bundle-adjusted with each frame's pose, refine the head's motion "
         "between frames; off keeps the poses from the landmarks.",
         "head-pose-features");
}

std::string FocalUncertaintyText(double log_sigma) {
  if (!(log_sigma > 0)) return "";
  // The covariance's figure covers the landmarks' scatter, not a face the
  // model fits with a bias: on talking_static's subjects the estimate is
  // 3-22 % off where this says 2.3-2.6 % (docs/calibration.md).
  char text[64];
  std::snprintf(text, sizeof(text), " (+-%.1f%% landmark noise only)", 100 * (std::exp(log_sigma) - 1));
  return text;
}

std::string CalibrateSummary::OneLine() const {
  char text[320];
  if (mode == "head-pose")
    std::snprintf(text, sizeof(text),
                  "head-pose: %d/%d frames, focal %.1f px%s, median landmark error %.2f px (%.2f source px)", registered,
                  total, focal, FocalUncertaintyText(focal_log_sigma).c_str(), reprojection_px, reprojection_source_px);
  else
    std::snprintf(text, sizeof(text), "%s: %d/%d frames registered, reprojection %.2f px", mode.c_str(), registered,
                  total, reprojection_px);
  return std::string(text) + (reason.empty() ? "" : " (" + reason + ")");
}

double HeadPosePriorFocal(const HeadPoseOptions& options, const IngestedCapture& capture) {
  if (!(options.prior_sigma > 0) || capture.cameras.empty()) return 0;
  const IngestedCamera& cam = capture.cameras[0];
  if (cam.source_width <= 0 || !(cam.crop_scale > 0)) return 0;
  return FocalFromFov(options.prior_fov_deg, cam.source_width, cam.crop_scale);
}

namespace {

Status HeadPoseCameras(const CalibrateOptions& options, const IngestedCapture& capture, const FaceModel& model,
                       CameraSet* cameras, CalibrateSummary* summary) {
  if (capture.cameras.size() != 1)
    return Status::InvalidArgument("head-pose cameras need exactly one video, got " +
                                   std::to_string(capture.cameras.size()));
  const IngestedCamera& cam = capture.cameras[0];
  if (!cam.fixed_crop)
    return Status::InvalidArgument("head-pose cameras need a fixed crop (ingest --crop sequence or none)");
  std::vector<std::optional<Landmarks68>> landmarks;
  for (const auto& f : cam.frames) landmarks.push_back(f.landmarks);
  const Eigen::Vector2d principal(cam.SourceCentreX(), cam.SourceCentreY());
  HeadPoseOptions head_pose = options.head_pose;
  if (head_pose.fov_deg > 0) {
    head_pose.focal = FocalFromFov(head_pose.fov_deg, cam.source_width, cam.crop_scale);
    head_pose.fov_deg = 0;
    HF_LOG(Info) << "calibrate: --fov " << options.head_pose.fov_deg << " over " << cam.source_width
                 << " source px: focal " << head_pose.focal << " frame px";
  }
  head_pose.landmark_points = DetectorLandmarkPoints(model, options.landmark_embedding);
  head_pose.prior_focal = HeadPosePriorFocal(head_pose, capture);
  HeadPoseResult result;
  HF_RETURN_IF_ERROR(EstimateHeadPoseCameras(model, landmarks, cam.width, cam.height, principal, head_pose, &result));
  CameraSet set;
  set.mode = "head-pose";
  set.frame = "head";
  set.notes = "cam_from_world is cam_from_head: the head frame of the face model serves as the world";
  CameraIntrinsics in;
  in.name = cam.name;
  in.model = "PINHOLE";
  in.width = cam.width;
  in.height = cam.height;
  in.fx = in.fy = result.focal;
  in.cx = principal.x();
  in.cy = principal.y();
  set.cameras.push_back(in);
  int observed = 0;
  for (size_t i = 0; i < cam.frames.size(); ++i) {
    CameraView v;
    v.camera = cam.name;
    v.frame = cam.frames[i].index;
    v.registered = true;  // interpolated where the face was lost
    v.cam_from_world = result.cam_from_head[i];
    set.views.push_back(v);
    observed += result.observed[i];
  }
  summary->mode = "head-pose";
  summary->registered = observed;
  summary->total = static_cast<int>(cam.frames.size());
  summary->focal = result.focal;
  summary->focal_log_sigma = result.focal_log_sigma;
  summary->reprojection_px = result.median_px;
  summary->reprojection_source_px = result.median_px / cam.crop_scale;
  *cameras = std::move(set);
  return Status::Ok();
}

// Equal lens parameters, up to the precision of a text model.
bool SameIntrinsics(const CameraIntrinsics& a, const CameraIntrinsics& b) {
  auto near = [](double x, double y) { return std::abs(x - y) <= 1e-6 * std::max(1.0, std::abs(x)); };
  return a.model == b.model && a.width == b.width && a.height == b.height && near(a.fx, b.fx) && near(a.fy, b.fy) &&
         near(a.cx, b.cx) && near(a.cy, b.cy) && near(a.k1, b.k1) && near(a.k2, b.k2) && near(a.p1, b.p1) &&
         near(a.p2, b.p2);
}

}  // namespace

Status ImportRig(const std::string& path, const IngestedCapture& capture, CameraSet* cameras) {
  std::map<std::string, std::pair<CameraIntrinsics, Eigen::Isometry3d>> rig;
  double metres_per_unit = 0;  // the rig file's own word; a COLMAP model has no unit
  std::error_code ec;
  if (fs::is_directory(path, ec)) {
    // A COLMAP text model: image names "<camera>/..." or "<camera>.<ext>" name the camera.
    // Several images may name one camera (a rig seen at several instants):
    // they must agree, since a fixed camera has one pose and one lens.
    ColmapTextModel model;
    HF_RETURN_IF_ERROR(ReadColmapCamerasAndImages(path, &model).WithContext("rig folder"));
    CameraSet instants;
    for (const auto& [name, image] : model.images) {
      const std::string camera = name.find('/') != std::string::npos ? name.substr(0, name.find('/'))
                                                                     : fs::path(name).stem().string();
      const CameraIntrinsics& in = model.cameras.at(image.first);
      const auto [it, first] = rig.insert({camera, {in, image.second}});
      if (!first && !SameIntrinsics(it->second.first, in))
        return Status::DataError("rig folder " + path + ": the images of camera " + camera +
                                 " have different intrinsics (COLMAP camera ids with other parameters); a fixed "
                                 "camera has one lens");
      CameraView view;
      view.camera = camera;
      view.registered = true;
      view.cam_from_world = image.second;
      instants.views.push_back(view);
    }
    if (Status s = CheckFixedCameraInstants(instants, ColmapOptions().max_instant_rotation_deg,
                                            ColmapOptions().max_instant_shift);
        !s.ok())
      return Status::DataError("rig folder " + path + ": " + s.message() +
                               "; a fixed camera has one pose: keep one image per camera in the folder");
  } else {
    nlohmann::json j;
    HF_RETURN_IF_ERROR(ReadJson(path, &j).WithContext("rig file"));
    try {
      metres_per_unit = j.value("metres_per_unit", 0.0);
      for (const auto& c : j.at("cameras")) {
        const CameraIntrinsics in = CameraIntrinsics::FromJson(c);
        rig[in.name] = {in, PoseFromJson(c.at("cam_from_world"))};
      }
    } catch (const nlohmann::json::exception& e) {
      return Status::DataError("rig file " + path + ": " + e.what());
    }
  }
  CameraSet set;
  set.mode = "rig";
  set.frame = "world";
  set.notes = "imported from " + path;
  if (!(metres_per_unit >= 0) || !std::isfinite(metres_per_unit))
    return Status::DataError("rig file " + path + ": metres_per_unit must be a positive number (1 for metres, 0.001 "
                             "for millimetres) or absent");
  set.metres_per_unit = metres_per_unit;
  for (const auto& cam : capture.cameras) {
    const auto it = rig.find(cam.name);
    if (it == rig.end()) return Status::DataError("rig file " + path + " has no camera named " + cam.name);
    CameraIntrinsics in = it->second.first;
    if (!cam.fixed_crop) return Status::InvalidArgument("rig import needs a fixed crop (ingest --crop sequence or none)");
    if (in.width != cam.source_width || in.height != cam.source_height)
      return Status::DataError("rig camera " + cam.name + " is " + std::to_string(in.width) + "x" +
                               std::to_string(in.height) + " but its video is " + std::to_string(cam.source_width) +
                               "x" + std::to_string(cam.source_height));
    // Source pixels -> frame pixels through ingest's crop.
    in.fx *= cam.crop_scale;
    in.fy *= cam.crop_scale;
    in.cx = (in.cx + 0.5 - cam.crop_x0) * cam.crop_scale - 0.5;
    in.cy = (in.cy + 0.5 - cam.crop_y0) * cam.crop_scale - 0.5;
    in.width = cam.width;
    in.height = cam.height;
    in.name = cam.name;
    set.cameras.push_back(in);
    for (const auto& f : cam.frames) {
      CameraView v;
      v.camera = cam.name;
      v.frame = f.index;
      v.registered = true;
      v.cam_from_world = it->second.second;
      set.views.push_back(v);
    }
  }
  *cameras = std::move(set);
  return Status::Ok();
}

Status RunCalibrate(const CalibrateOptions& options, const IngestedCapture& capture, const FaceModel& model,
                    const fs::path& out_dir, Progress* progress, CameraSet* cameras, CalibrateSummary* summary) {
  HF_RETURN_IF_ERROR(options.Check());
  *summary = CalibrateSummary();
  std::string mode = options.mode;
  ColmapOptions colmap = options.colmap;
  if (capture.cameras.size() > 1 && options.static_rig != "no") {
    // Several cameras: a rig of fixed cameras is calibrated from synchronised frames.
    bool fixed = options.static_rig == "yes";
    if (options.static_rig == "auto") {
      fixed = true;
      for (const auto& cam : capture.cameras) {
        BackgroundMotion motion;
        HF_RETURN_IF_ERROR(MeasureBackgroundMotion(capture, cam.name, &motion));
        fixed = fixed && !motion.Moving(options.motion_threshold_px);
      }
    }
    colmap.static_cameras = fixed;
    if (fixed) HF_LOG(Info) << "calibrate: the " << capture.cameras.size() << " cameras do not move: calibrating the rig from "
                            << colmap.rig_instants << " synchronised instant(s)";
  }
  if (mode == "auto") {
    if (capture.cameras.size() > 1) {
      mode = "colmap";
      summary->reason = "auto: " + std::to_string(capture.cameras.size()) + " cameras";
    } else {
      BackgroundMotion motion;
      HF_RETURN_IF_ERROR(MeasureBackgroundMotion(capture, capture.cameras[0].name, &motion));
      const bool moving = motion.Moving(options.motion_threshold_px);
      mode = moving ? "colmap" : "head-pose";
      summary->reason = "auto: " + motion.Describe() + (moving ? ": a moving camera" : ": a fixed camera");
    }
    HF_LOG(Info) << "calibrate: " << summary->reason << " -> " << mode;
  }
  if (mode == "rig") {
    HF_RETURN_IF_ERROR(ImportRig(options.rig, capture, cameras));
    summary->mode = "rig";
    summary->registered = summary->total = static_cast<int>(cameras->views.size());
    return cameras->Write(out_dir / "cameras.json");
  }
  if (mode == "head-pose") {
    HF_RETURN_IF_ERROR(HeadPoseCameras(options, capture, model, cameras, summary));
    return cameras->Write(out_dir / "cameras.json");
  }
  for (const auto& cam : capture.cameras)
    if (!cam.fixed_crop)
      return Status::InvalidArgument("COLMAP needs one camera model per video, but " + cam.name +
                                     " was ingested with a crop that follows the head (--crop frame); ingest it "
                                     "again with --crop none or sequence");
  progress->Start("calibrate: COLMAP", 0);
  ColmapReport report;
  Status status = RunColmap(colmap, capture, out_dir / "colmap", cameras, &report);
  progress->Finish();
  if (report.sequential_registered >= 0) {
    summary->sequential_registered = report.sequential_registered;
    summary->keyframe_step = report.keyframe_step;
    std::string then;
    if (report.keyframes > 0)
      then += ", then " + std::to_string(report.keyframes) + " keyframes (one image in " +
              std::to_string(report.keyframe_step) + ") were mapped and the rest registered";
    if (report.exhaustive_fallback) then += ", then every pair was matched";
    summary->reason += (summary->reason.empty() ? "" : "; ") + std::string("sequential matching registered ") +
                       std::to_string(report.sequential_registered) + " of " + std::to_string(report.total) + then;
  }
  summary->revisit_pairs = report.revisit_pairs;
  if (report.revisit_pairs > 0)
    summary->reason += (summary->reason.empty() ? "" : "; ") + std::to_string(report.revisit_pairs) +
                       " pairs of revisited views matched";
  const bool too_few = status.ok() && report.registered < options.min_registered * report.total;
  if (status.ok() && !too_few) {
    summary->mode = "colmap";
    summary->registered = report.registered;
    summary->total = report.total;
    summary->reprojection_px = report.mean_reprojection_px;
    HF_LOG(Info) << "calibrate: COLMAP registered " << report.registered << "/" << report.total << " frames in "
                 << report.seconds << " s";
    return cameras->Write(out_dir / "cameras.json");
  }
  const std::string what = status.ok() ? "COLMAP registered only " + std::to_string(report.registered) + " of " +
                                             std::to_string(report.total) + " frames (below --min-registered " +
                                             std::to_string(static_cast<int>(100 * options.min_registered + 0.5)) +
                                             "%; see " + (out_dir / "colmap" / "colmap.log").string() + ")"
                                       : status.message();
  if (options.mode != "auto" || capture.cameras.size() != 1)
    return Status::DataError(what + ". Try: more texture in the background, --max-features 8192, --matcher "
                             "exhaustive, or --mode head-pose for a fixed camera");
  HF_LOG(Warning) << "calibrate: " << what << "; falling back to head-pose cameras";
  // colmap/ stays, so that the log named in `what` can be read.
  summary->reason += (summary->reason.empty() ? "" : "; ") + what + "; fell back to head-pose";
  const std::string reason = summary->reason;
  HF_RETURN_IF_ERROR(HeadPoseCameras(options, capture, model, cameras, summary));
  summary->reason = reason;
  return cameras->Write(out_dir / "cameras.json");
}

}  // namespace headforge
