#include "reconstruction/track_stage.h"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <fstream>
#include <map>
#include <numeric>

#include "calibration/feature_poses.h"
#include "calibration/landmark_embedding.h"
#include "core/log.h"
#include "core/video_writer.h"
#include "core/mesh_renderer.h"
#include "core/parallel.h"
#include "reconstruction/tracking_io.h"

namespace headforge {
namespace {

TrackingCamera ToTrackingCamera(const CameraIntrinsics& in, const Eigen::Isometry3d& cam_from_head) {
  TrackingCamera c;
  c.fx = in.fx;
  c.fy = in.fy > 0 ? in.fy : in.fx;
  c.cx = in.cx;
  c.cy = in.cy;
  c.rotation = cam_from_head.linear();
  c.translation = cam_from_head.translation();
  return c;
}

// One TrackingView per registered view of every camera, with its landmarks;
// `view_source` says where each came from: (camera index, position in that
// camera's ingested frames).
Status BuildTrackingViews(const IngestedCapture& capture, const CameraSet& cameras, std::vector<TrackingView>* views,
                          std::vector<std::pair<int, int>>* view_source) {
  for (size_t c = 0; c < capture.cameras.size(); ++c) {
    const IngestedCamera& cam = capture.cameras[c];
    const CameraIntrinsics* in = cameras.FindCamera(cam.name);
    if (in == nullptr) return Status::DataError("track: no intrinsics for camera " + cam.name + " in the cameras");
    for (size_t k = 0; k < cam.frames.size(); ++k) {
      const IngestedFrame& f = cam.frames[k];
      const CameraView* v = cameras.FindView(cam.name, f.index);
      if (v == nullptr || !v->registered) continue;  // an unregistered view says nothing
      TrackingView view;
      view.frame = f.index;
      view.camera = ToTrackingCamera(*in, v->cam_from_world);
      if (f.landmarks) {
        // The fit's cameras are pinholes: lens distortion comes off the landmarks here.
        std::array<Eigen::Vector2d, 68> points;
        for (int i = 0; i < 68; ++i) points[i] = in->Undistort(Eigen::Vector2d((*f.landmarks)[i].x, (*f.landmarks)[i].y));
        view.landmarks = points;
        for (const cv::Point3f& p : f.mesh) view.mesh.push_back(in->Undistort(Eigen::Vector2d(p.x, p.y)));
      }
      views->push_back(view);
      view_source->emplace_back(int(c), int(k));
    }
  }
  return Status::Ok();
}

// The face mesh's basis from its embedding file: empty (no mesh) for "",
// and with a warning where the file is missing.
Status LoadMeshBasis(const FaceModel& model, const std::string& path, int identity_modes, LandmarkBasis* basis) {
  *basis = LandmarkBasis();
  if (path.empty()) return Status::Ok();
  if (!fs::exists(path)) {
    HF_LOG(Warning) << "the face mesh embedding " << path << " is missing: the 68 points are fitted alone";
    return Status::Ok();
  }
  std::vector<Eigen::Vector3d> points;
  HF_RETURN_IF_ERROR(ReadMeshEmbedding(path, &points));
  return BuildLandmarkBasis(model, points, identity_modes, basis);
}

// Each view's landmark basis for the direction its camera sees the head
// from, the head moved by `motion` of its frame (none: at its initial pose);
// nothing when the embedding is the same from every direction.
void AttachViewBases(const ViewLandmarkBases& bases, const std::vector<Eigen::Isometry3d>& motion,
                     std::vector<TrackingView>* views) {
  if (bases.nodes.empty()) return;
  for (TrackingView& view : *views) {
    Eigen::Vector3d centre = view.camera.Centre();
    if (view.frame < int(motion.size())) centre = motion[view.frame].inverse() * centre;
    view.basis = std::make_shared<const LandmarkBasis>(bases.ForDirection(centre));
  }
}

// The fitted head drawn over one frame: the face shaded toward the camera at
// half opacity, detected landmarks green, fitted ones red.
cv::Mat Overlay(const cv::Mat& frame, const Mesh& mesh, const TrackingCamera& camera,
                const std::optional<std::array<Eigen::Vector2d, 68>>& detected,
                const std::vector<Eigen::Vector2d>& fitted) {
  PinholeCamera pinhole;
  pinhole.fx = camera.fx;
  pinhole.fy = camera.fy;
  pinhole.cx = camera.cx;
  pinhole.cy = camera.cy;
  pinhole.width = frame.cols;
  pinhole.height = frame.rows;
  pinhole.cam_from_world.linear() = camera.rotation;
  pinhole.cam_from_world.translation() = camera.translation;
  RenderOptions options;
  options.supersample = 1;
  options.threads = 1;
  options.lighting.enabled = true;
  // Light from the camera: its viewing axis in the head frame, reversed.
  options.lighting.direction = (-camera.rotation.transpose() * Eigen::Vector3d::UnitZ()).cast<float>();
  RenderOutput out;
  RenderMeshes({&mesh}, pinhole, options, &out);
  cv::Mat image = frame.clone();
  for (int y = 0; y < image.rows; ++y) {
    for (int x = 0; x < image.cols; ++x) {
      if (out.triangle.at<int32_t>(y, x) < 0) continue;
      const cv::Vec3f c = out.color.at<cv::Vec3f>(y, x) * 255.0f;
      cv::Vec3b& p = image.at<cv::Vec3b>(y, x);
      for (int k = 0; k < 3; ++k) p[k] = cv::saturate_cast<uint8_t>(0.5f * p[k] + 0.5f * c[k]);
    }
  }
  if (detected) {
    for (const auto& p : *detected) cv::circle(image, cv::Point2d(p.x(), p.y()), 1, cv::Scalar(0, 255, 0), -1);
  }
  for (const auto& p : fitted) cv::circle(image, cv::Point2d(p.x(), p.y()), 1, cv::Scalar(0, 0, 255), -1);
  return image;
}

Status WriteObj(const fs::path& path, const Eigen::Matrix3Xf& vertices, const Eigen::Matrix3Xi& triangles) {
  std::ostringstream text;
  text.precision(6);
  for (int i = 0; i < vertices.cols(); ++i)
    text << "v " << vertices(0, i) << " " << vertices(1, i) << " " << vertices(2, i) << "\n";
  for (int t = 0; t < triangles.cols(); ++t)
    text << "f " << triangles(0, t) + 1 << " " << triangles(1, t) + 1 << " " << triangles(2, t) + 1 << "\n";
  return WriteFileAtomic(path, text.str());
}

}  // namespace

Status TrackStageOptions::Check() const {
  std::string why;
  if (!fit.Check(&why)) return Status::InvalidArgument("track: " + why);
  if (!(grid_min_span_deg >= 0)) return Status::InvalidArgument("track: grid_min_span must be zero or positive");
  if (!(multiview_contour_weight >= 0))
    return Status::InvalidArgument("track: multiview_contour_weight must be zero or positive");
  if (!(multiview_mesh_weight >= 0))
    return Status::InvalidArgument("track: multiview_mesh_weight must be zero or positive");
  if (head_motion != "auto" && head_motion != "free" && head_motion != "still")
    return Status::InvalidArgument("track: --head-motion must be auto, free or still, not '" + head_motion + "'");
  return Status::Ok();
}

void AddTrackOptions(OptionSet* o, TrackStageOptions* t) {
  o->Add("track.identity_modes", &t->fit.identity_modes, "Identity (shape) modes fitted, shared by the sequence.",
         "identity-modes");
  o->Add("track.identity_prior", &t->fit.identity_prior,
         "Weight of the identity's unit Gaussian prior (pixels per standard deviation).", "identity-prior");
  o->Add("track.expression_sparsity", &t->fit.expression_sparsity,
         "L1-like prior on blendshape weights (squared pixels per unit of weight).", "expression-sparsity");
  o->Add("track.rotation_smoothness", &t->fit.rotation_smoothness,
         "Temporal smoothness of head rotation (pixels per radian between frames).", "rotation-smoothness");
  o->Add("track.translation_smoothness", &t->fit.translation_smoothness,
         "Temporal smoothness of head translation (pixels per metre between frames).", "translation-smoothness");
  o->Add("track.expression_smoothness", &t->fit.expression_smoothness,
         "Temporal smoothness of blendshape weights (pixels per unit between frames).", "expression-smoothness");
  o->Add("track.robust_scale_px", &t->fit.robust_scale_px, "Huber scale of landmark residuals, pixels.",
         "robust-scale");
  o->Add("track.contour_weight", &t->fit.contour_weight, "Weight of the jaw-contour landmarks (0-16).",
         "contour-weight");
  o->Add("track.contour_max_yaw", &t->fit.contour_max_yaw_deg,
         "Views turned further than this from the face (degrees) leave their jaw contour out (fading over the 10 "
         "degrees before); 180 keeps all.",
         "contour-max-yaw");
  o->Add("track.max_view_yaw", &t->fit.max_fit_yaw_deg,
         "A frame seen within this yaw of frontal (degrees) by some camera ignores its other views.",
         "max-view-yaw");
  o->Add("track.max_iterations", &t->fit.max_iterations, "Levenberg-Marquardt iterations at most.",
         "track-iterations");
  o->Add("track.landmark_embedding", &t->landmark_embedding,
         "Where the detector's 68 landmarks sit on the face model (JSON; embed-landmarks); empty: the shipped view "
         "grid when the views of a frame see the head from directions more than --grid-min-span apart in yaw, else "
         "the shipped points with their identity columns (embed-landmarks --identity).",
         "track-landmark-embedding", OptionSet::Effect::kRuntime);  // its contents count instead (the job's inputs)
  o->Add("track.mesh_embedding", &t->mesh_embedding,
         "Where the face mesh's 468 points sit on the face model (JSON; embed-landmarks --mesh), for --mesh-weight.",
         "track-mesh-embedding", OptionSet::Effect::kRuntime);  // its contents count instead (the job's inputs)
  o->Add("track.mesh_weight", &t->fit.mesh_weight,
         "Fit the face mesh's 468 points (where ingest found them) beside the 68 landmarks, each at this weight "
         "against 1 for a landmark (0, the default: the 68 alone). 0.4 gave a simulated talking head's avatar "
         "4-6 dB better novel views and its tracked head rotation 0.5 deg more error (docs/vision.md).",
         "mesh-weight");
  o->Add("track.grid_min_span", &t->grid_min_span_deg,
         "The spread of one frame's views' yaws about the head (degrees) above which the views surround the head: "
         "each then uses the detector's points as seen from its side (with the default embedding), and the jaw "
         "contour weighs --multiview-contour-weight.",
         "grid-min-span");
  o->Add("track.multiview_contour_weight", &t->multiview_contour_weight,
         "Weight of the jaw-contour landmarks instead of --contour-weight when the views of a frame see the head "
         "from more than --grid-min-span apart in yaw (a rig around the face).",
         "multiview-contour-weight");
  o->Add("track.multiview_mesh_weight", &t->multiview_mesh_weight,
         "Weight of the face mesh's points instead of --mesh-weight when the views of a frame see the head from "
         "more than --grid-min-span apart in yaw (a rig around the face; 0, the default: --mesh-weight stays). The "
         "68-point predictor reads turned faces as nearly frontal: on the unlit dome_360 0.4 took the tracked head "
         "from 9.8 to 2.3 deg off; on the lit rig_8cam it cost the smile's weights (docs/tracking.md).",
         "multiview-mesh-weight");
  o->Add("track.refine_head_pose", &t->refine_head_pose,
         "With head-pose cameras, refine each frame's head pose with the fitted shape (false: hold it). Cameras "
         "whose poses calibrate refined by the head's texture (--head-pose-features) are moved by one rotation and "
         "translation for all frames; --head-motion free refits each frame's.",
         "refine-head-pose");
  o->Add("track.head_motion", &t->head_motion,
         "Each frame's head motion: free, still (held at rest; the cameras carry every change of view: a head that "
         "holds still while the camera goes round it) or auto (still for one camera carried 120 degrees or more "
         "round the head, free otherwise).",
         "head-motion");
  o->Add("track.overlay", &t->overlay, "Write overlay_<camera>.mp4: the fitted mesh over the frames.", "overlay");
  o->Add("track.meshes", &t->meshes, "Write meshes/<frame>.obj: the fitted head per frame (head frame).",
         "meshes");
}

namespace {

// The widest spread, over the frames, of the yaws (degrees, about the head)
// from which one frame's views see the head.
double WidestViewSpread(const std::vector<TrackingView>& views) {
  std::map<int, std::pair<double, double>> yaws;  // frame -> lowest, highest yaw of its views
  double widest = 0;
  for (const TrackingView& view : views) {
    if (!view.landmarks) continue;
    const Eigen::Vector3d c = view.camera.Centre();
    const double yaw = std::atan2(c.x(), c.z()) * 180.0 / M_PI;
    const auto [it, first] = yaws.emplace(view.frame, std::make_pair(yaw, yaw));
    it->second.first = std::min(it->second.first, yaw);
    it->second.second = std::max(it->second.second, yaw);
    widest = std::max(widest, it->second.second - it->second.first);
  }
  return widest;
}

// Fits the sequence; with view-dependent points, a second time with each
// view's points for the direction the first fit turned the head to.
Status FitSequence(const ViewLandmarkBases& bases, const LandmarkBasis* mesh, const TrackOptions& fit, int num_frames,
                   std::vector<TrackingView>* views, TrackResult* result) {
  AttachViewBases(bases, {}, views);
  HF_RETURN_IF_ERROR(TrackSequence(bases.any_view, *views, num_frames, fit, result, mesh));
  if (bases.nodes.empty() || fit.fixed_head) return Status::Ok();
  std::vector<Eigen::Isometry3d> motion;
  for (const TrackedFrame& f : result->frames) motion.push_back(f.head_motion);
  AttachViewBases(bases, motion, views);
  const double first_seconds = result->seconds;
  HF_RETURN_IF_ERROR(TrackSequence(bases.any_view, *views, num_frames, fit, result, mesh));
  result->seconds += first_seconds;
  return Status::Ok();
}

// The fitted head of a frame, moved by its head motion.
Eigen::Matrix3Xf FittedVertices(const FaceModel& model, const Eigen::Matrix3Xf& identity_shape,
                                const TrackedFrame& f) {
  Eigen::Matrix3Xf v = identity_shape;
  model.AddExpression(f.expression.cast<float>(), &v);
  return (f.head_motion.cast<float>() * v.colwise().homogeneous()).topRows(3);
}

Status WriteMeshes(const FaceModel& model, const TrackResult& result, const fs::path& dir) {
  HF_RETURN_IF_ERROR(EnsureDirectory(dir));
  const Eigen::Matrix3Xf identity_shape = model.Identity(result.identity.cast<float>());
  for (const TrackedFrame& f : result.frames) {
    char name[32];
    std::snprintf(name, sizeof(name), "%06d.obj", f.frame);
    HF_RETURN_IF_ERROR(WriteObj(dir / name, FittedVertices(model, identity_shape, f), model.triangles()));
  }
  return Status::Ok();
}

// overlay_<camera>.mp4 for every camera: the fitted face shaded over each
// frame with the detected (green) and fitted (red) landmarks.
Status WriteOverlays(const FaceModel& model, const IngestedCapture& capture, const CameraSet& cameras,
                     const std::vector<TrackingView>& views, const std::vector<std::pair<int, int>>& view_source,
                     const LandmarkBasis& basis, const TrackResult& result, const fs::path& out_dir,
                     Progress* progress, std::vector<std::string>* outputs) {
  // Only the face is drawn (the rest of the head has no landmarks to follow).
  Mesh mesh;
  mesh.triangles = model.triangles();
  mesh.material.assign(model.num_triangles(), -1);
  const FaceModel::Region* face = model.FindRegion("face");
  for (int t = 0; t < model.num_triangles(); ++t) {
    if (face == nullptr || face->ContainsTriangle(t)) mesh.material[t] = 0;
  }
  Material skin;
  skin.colour = Eigen::Vector3f(0.75f, 0.8f, 0.85f);
  mesh.materials = {skin};
  const Eigen::Matrix3Xf identity_shape = model.Identity(result.identity.cast<float>());
  // Frame by frame, so each frame's mesh is built once for all its views.
  std::vector<size_t> order(views.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return views[a].frame < views[b].frame; });
  progress->Start("track: overlay video", int64_t(views.size()));
  std::map<int, VideoFileWriter> writers;
  int mesh_frame = -1;
  for (const size_t i : order) {
    const auto [c, position] = view_source[i];
    const int frame = views[i].frame;
    const IngestedCamera& cam = capture.cameras[c];
    const cv::Mat image = cv::imread(capture.FramePath(cam.name, frame).string(), cv::IMREAD_COLOR);
    if (image.empty()) return Status::IoError("track: cannot read frame " + capture.FramePath(cam.name, frame).string());
    const TrackedFrame& f = result.frames[frame];
    if (frame != mesh_frame) {
      mesh.vertices = FittedVertices(model, identity_shape, f);
      mesh.normals = VertexNormals(mesh.vertices, mesh.triangles);
      mesh_frame = frame;
    }
    // Landmarks as detected and fitted ones through the lens (the shaded mesh is drawn without distortion).
    const CameraIntrinsics& lens = *cameras.FindCamera(cam.name);
    std::vector<Eigen::Vector2d> fitted;
    const LandmarkBasis& seen_by = views[i].basis ? *views[i].basis : basis;
    for (int l = 0; l < 68; ++l) {
      const Eigen::Vector3d head = f.head_motion * seen_by.Point(l, result.identity, f.expression);
      fitted.push_back(lens.Project(views[i].camera.rotation * head + views[i].camera.translation));
    }
    std::optional<std::array<Eigen::Vector2d, 68>> detected;
    if (const auto& lm = cam.frames[position].landmarks) {
      detected.emplace();
      for (int l = 0; l < 68; ++l) (*detected)[l] = Eigen::Vector2d((*lm)[l].x, (*lm)[l].y);
    }
    const cv::Mat drawn = Overlay(image, mesh, views[i].camera, detected, fitted);
    auto it = writers.find(c);
    if (it == writers.end()) {
      const fs::path video = out_dir / ("overlay_" + cam.name + ".mp4");
      VideoFileWriter writer;
      HF_RETURN_IF_ERROR(writer.Open(video, capture.fps, drawn.size()).WithContext("track"));
      it = writers.emplace(c, std::move(writer)).first;
      outputs->push_back(video.filename().string());
    }
    HF_RETURN_IF_ERROR(it->second.Write(drawn));
    progress->Advance();
  }
  for (auto& [camera, writer] : writers) HF_RETURN_IF_ERROR(writer.Close().WithContext("track"));
  progress->Finish();
  return Status::Ok();
}

}  // namespace

Status RunTrack(const TrackStageOptions& options, const IngestedCapture& capture, const CameraSet& cameras,
                const FaceModel& model, const fs::path& out_dir, Progress* progress, TrackSummary* summary) {
  HF_RETURN_IF_ERROR(options.Check());
  if (cameras.frame != "head") {
    return Status::InvalidArgument("track: the cameras are not in the head frame; run align first (cameras_head.json)");
  }
  if (model.num_expressions() == 0) return Status::DataError("track: the face model has no expressions");
  TrackOptions fit = options.fit;
  const bool still = options.head_motion == "still" || (options.head_motion == "auto" && cameras.mode != "head-pose" &&
                                                        cameras.WalksRoundTheHead());
  fit.fixed_head = still || (cameras.mode == "head-pose" && !options.refine_head_pose && options.head_motion != "free");
  // Head-pose cameras that features refined carry the head's motion from
  // frame to frame better than the landmarks would refit it: the fit moves
  // the head frame once for every frame.
  fit.one_head_motion =
      cameras.mode == "head-pose" && cameras.poses_from_features && !fit.fixed_head && options.head_motion != "free";
  fit.samples = capture.samples;

  std::vector<TrackingView> views;
  std::vector<std::pair<int, int>> view_source;  // camera index, position in its frames
  HF_RETURN_IF_ERROR(BuildTrackingViews(capture, cameras, &views, &view_source));
  const double widest = WidestViewSpread(views);
  const bool surrounded = widest > options.grid_min_span_deg;
  if (surrounded) {
    // Each view draws the jaw contour where its own side of the face turns
    // away; the inner points agree between views and set the head's pose.
    fit.contour_weight = options.multiview_contour_weight;
    if (options.multiview_mesh_weight > 0) fit.mesh_weight = options.multiview_mesh_weight;
    HF_LOG(Info) << "track: the views of a frame see the head from up to " << std::lround(widest)
                 << " deg apart: the jaw contour weighs " << fit.contour_weight << ", the face mesh "
                 << fit.mesh_weight
                 << (options.landmark_embedding.empty() ? ", and each view uses the detector's points as seen from its side"
                                                        : "");
  }
  std::string embedding = options.landmark_embedding;
  if (embedding.empty()) {
    // Views of one frame fitted together must agree on the head: from far
    // apart each sees the detector's points where they fall from its side.
    // Views from one side, or one view per frame (a single camera, an orbit),
    // use the points measured over +-25 degrees on many subjects, which move
    // with the fitted identity the way the detector's points do.
    embedding = surrounded ? ViewLandmarkEmbedding() : IdentityLandmarkEmbedding();
  }
  ViewLandmarkBases bases;
  HF_RETURN_IF_ERROR(BuildViewLandmarkBases(model, LoadLandmarkEmbedding(model, embedding), options.fit.identity_modes,
                                            &bases));
  const int num_frames = capture.num_frames();
  HF_LOG(Info) << "track: " << views.size() << " views of " << num_frames << " frames, " << options.fit.identity_modes
               << " identity modes, " << model.num_expressions() << " expressions"
               << (still ? ", the head held still (one camera carried round it; --head-motion free fits its motion)"
                   : fit.fixed_head ? ", head held by the head-pose cameras"
                   : fit.one_head_motion ? ", the head frame moved once for every frame (cameras refined by features)" : "");
  progress->Start("track: fitting", 0);
  TrackResult result;
  LandmarkBasis mesh;
  if (fit.mesh_weight > 0)
    HF_RETURN_IF_ERROR(LoadMeshBasis(model, options.mesh_embedding, options.fit.identity_modes, &mesh));
  HF_RETURN_IF_ERROR(FitSequence(bases, mesh.size() > 0 ? &mesh : nullptr, fit, num_frames, &views, &result));
  progress->Finish(result.solver_report);

  TrackingFile tracking;
  tracking.face_model = model.path();
  tracking.identity_modes = options.fit.identity_modes;
  tracking.identity = result.identity;
  tracking.expression_names = model.expression_names();
  tracking.head_held_by_cameras = fit.fixed_head;
  tracking.median_residual_px = result.median_residual_px;
  tracking.dropped_views = result.dropped_views;
  tracking.landmark_embedding = embedding;
  tracking.view_dependent_landmarks = !bases.nodes.empty();
  tracking.contour_weight = fit.contour_weight;
  tracking.solver = result.solver_report;
  tracking.seconds = result.seconds;
  tracking.frames = result.frames;
  HF_RETURN_IF_ERROR(WriteTracking(tracking, out_dir / "tracking.json"));
  summary->outputs = {"tracking.json"};
  if (options.meshes) {
    HF_RETURN_IF_ERROR(WriteMeshes(model, result, out_dir / "meshes"));
    summary->outputs.push_back("meshes");
  }
  if (options.overlay)
    HF_RETURN_IF_ERROR(WriteOverlays(model, capture, cameras, views, view_source, bases.any_view, result, out_dir,
                                     progress, &summary->outputs));
  summary->frames = num_frames;
  summary->interpolated = summary->low_confidence = 0;
  for (const TrackedFrame& f : result.frames) {
    summary->interpolated += f.interpolated;
    summary->low_confidence += f.low_confidence;
  }
  summary->median_residual_px = result.median_residual_px;
  summary->dropped_views = result.dropped_views;
  summary->seconds = result.seconds;
  summary->fixed_head = fit.fixed_head;
  return Status::Ok();
}

Status RefineHeadPoseCameras(const FaceModel& model, const IngestedCapture& capture, const TrackOptions& options,
                             const std::string& landmark_embedding, int max_rounds, double min_change,
                             double prior_focal, bool fit_focal, CameraSet* cameras, HeadPoseRefinement* result,
                             const std::string& mesh_embedding) {
  if (cameras->mode != "head-pose" || cameras->frame != "head")
    return Status::InvalidArgument("the face-model refinement applies to head-pose cameras");
  if (capture.cameras.size() != 1 || cameras->cameras.size() != 1)
    return Status::InvalidArgument("head-pose cameras have one camera");
  if (max_rounds < 1 || !(min_change > 0)) return Status::InvalidArgument("the refinement needs rounds >= 1, change > 0");
  if (model.num_expressions() == 0) return Status::DataError("the face model has no expressions");
  const std::string embedding = landmark_embedding.empty() ? DefaultLandmarkEmbedding() : landmark_embedding;
  // The points over every direction: a grid's points change as the head
  // turns, which the focal length's fit would read as perspective.
  LandmarkBasis basis;
  HF_RETURN_IF_ERROR(BuildLandmarkBasis(model, LoadLandmarkEmbedding(model, embedding), options.identity_modes, &basis));
  LandmarkBasis mesh;
  if (options.mesh_weight > 0) HF_RETURN_IF_ERROR(LoadMeshBasis(model, mesh_embedding, options.identity_modes, &mesh));
  TrackOptions fit = options;
  fit.fixed_head = false;
  fit.fit_focal = fit_focal;
  fit.samples = capture.samples;
  HeadPoseRefinement out;
  CameraIntrinsics& in = cameras->cameras[0];
  out.focal_before = in.fx;
  for (int round = 0; round < max_rounds; ++round) {
    std::vector<TrackingView> views;
    std::vector<std::pair<int, int>> view_source;
    HF_RETURN_IF_ERROR(BuildTrackingViews(capture, *cameras, &views, &view_source));
    fit.focal_prior_scale = prior_focal > 0 ? prior_focal / in.fx : 0;
    // The uncertainty of the last round's estimate; which round is last shows only after it.
    fit.focal_uncertainty = fit_focal;
    // Each round starts afresh from the mean face: started from the last
    // round's identity and expressions the focal length stays where round 1
    // left it (GRID's three speakers then spread 1.32x, against 1.15x).
    TrackResult tracked;
    HF_RETURN_IF_ERROR(TrackSequence(basis, views, capture.num_frames(), fit, &tracked, mesh.size() > 0 ? &mesh : nullptr));
    out.focal_log_sigma = tracked.focal_log_sigma;
    in.fx *= tracked.focal_scale;
    in.fy *= tracked.focal_scale;
    // The camera dollies with the zoom (tracking_costs.h), and the fitted
    // motion of the head becomes part of each frame's camera:
    // cam_from_head' = dollied cam_from_head * head_motion.
    for (CameraView& v : cameras->views) {
      if (!v.registered) continue;
      if (v.frame < 0 || v.frame >= int(tracked.frames.size()))
        return Status::DataError("head-pose cameras name frame " + std::to_string(v.frame) + " of " +
                                 std::to_string(tracked.frames.size()));
      v.cam_from_world.translation().z() *= tracked.focal_scale;
      v.cam_from_world = v.cam_from_world * tracked.frames[v.frame].head_motion;
    }
    out.rounds = round + 1;
    HF_LOG(Debug) << "head-pose refinement round " << out.rounds << ": focal x" << tracked.focal_scale << " -> "
                  << in.fx << " px, " << tracked.iterations << " iterations, " << tracked.seconds << " s";
    out.median_residual_px = tracked.median_residual_px;
    out.seconds += tracked.seconds;
    out.solver_report = tracked.solver_report;
    out.settled = std::abs(tracked.focal_scale - 1.0) < min_change;
    if (out.settled) break;
  }
  out.focal_after = in.fx;
  *result = out;
  return Status::Ok();
}

Status RefineHeadPoseStep(const CalibrateOptions& calibrate, const IngestedCapture& capture, const FaceModel& model,
                          int threads, Progress* progress, CameraSet* cameras, CalibrateSummary* summary,
                          bool* applied) {
  if (applied) *applied = false;
  if (summary->mode != "head-pose" || calibrate.head_pose.refine != "face-model") return Status::Ok();
  // A focal length the user gave stays; the poses are refined at it (fitted
  // to the mean face's landmarks alone they reproject them about twice as
  // far off: docs/benchmarks.md, what registration costs the avatar).
  const bool fit_focal = !calibrate.head_pose.FocalGiven();
  TrackOptions fit;
  fit.threads = threads > 0 ? threads : DefaultThreads();
  fit.focal_prior_sigma = calibrate.head_pose.prior_sigma;
  fit.mesh_weight = calibrate.head_pose.refine_mesh_weight;
  const double prior_focal = fit_focal ? HeadPosePriorFocal(calibrate.head_pose, capture) : 0.0;
  progress->Start("calibrate: refining with the face model", 0);
  HeadPoseRefinement refined;
  HF_RETURN_IF_ERROR(RefineHeadPoseCameras(model, capture, fit, calibrate.landmark_embedding,
                                           fit_focal ? calibrate.head_pose.refine_rounds : 1, 0.01, prior_focal,
                                           fit_focal, cameras, &refined, DefaultMeshEmbedding()));
  progress->Finish();
  std::string how;
  if (!fit_focal) {
    HF_LOG(Info) << "calibrate: the face model's identity and expressions refine the poses at the given focal length "
                 << refined.focal_after << " px (landmark residual " << refined.median_residual_px << " px, "
                 << refined.seconds << " s)";
    how = "poses refined with the face model at the given focal length";
  } else {
    if (!refined.settled)
      HF_LOG(Warning) << "calibrate: the focal length was still moving after " << refined.rounds
                      << " rounds of the face-model refinement (--head-pose-refine-rounds)";
    HF_LOG(Info) << "calibrate: the face model's identity and expressions move the focal length from "
                 << refined.focal_before << " to " << refined.focal_after << " px"
                 << FocalUncertaintyText(refined.focal_log_sigma) << " in " << refined.rounds
                 << " round(s) (landmark residual " << refined.median_residual_px << " px, " << refined.seconds << " s)";
    summary->focal = refined.focal_after;
    summary->focal_log_sigma = refined.focal_log_sigma;
    // A standard deviation of 15 % or more: the video does not fix the lens.
    if (refined.focal_log_sigma > 0.14)
      HF_LOG(Warning) << "calibrate: this video leaves the focal length poorly determined (" << refined.focal_after
                      << " px" << FocalUncertaintyText(refined.focal_log_sigma)
                      << "; the head barely turns or moves toward the camera): if you know the lens, give --fov DEG "
                         "(the video's horizontal field of view) or --focal PX";
    how = "refined with the face model from focal " +
          std::to_string(static_cast<int>(std::lround(refined.focal_before))) + " px";
  }
  if (calibrate.head_pose.features && !capture.cameras.empty()) {
    progress->Start("calibrate: following the head's texture", 0);
    FeaturePoseOptions features;
    features.threads = fit.threads;
    FeaturePoseStats moved;
    HF_RETURN_IF_ERROR(RefineHeadPosesWithFeatures(capture, capture.cameras[0].name, features, cameras, &moved));
    progress->Finish();
    HF_LOG(Info) << "calibrate: " << (moved.left.empty() ? "head poses refined by " : "features on the rigid face: ")
                 << moved.Summary();
    if (moved.frames_moved > 0) {
      how += "; poses refined by features on the rigid face";
      cameras->poses_from_features = true;
    }
  }
  summary->reprojection_px = refined.median_residual_px;
  if (!capture.cameras.empty() && capture.cameras[0].crop_scale > 0)
    summary->reprojection_source_px = refined.median_residual_px / capture.cameras[0].crop_scale;
  summary->reason += std::string(summary->reason.empty() ? "" : "; ") + how;
  if (applied) *applied = true;
  return Status::Ok();
}

}  // namespace headforge
