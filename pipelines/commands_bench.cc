// `headforge bench calibrate`: what camera accuracy costs in time. Simulates
// the orbit_360 and rig_8cam scenes (and talking_static for head-pose cameras),
// ingests them, runs calibrate and align at several settings and compares the
// cameras with the ground truth.
// `headforge bench track`: tracking accuracy over many subjects. Simulates
// talking_static with several random faces, calibrates head-pose cameras and
// tracks each with the plain landmark points and with the identity columns.
// `headforge bench truth-workspace`: a copy of a tracked workspace of a
// simulated capture with the simulator's cameras, expressions and identity in
// place of the tracked ones, to train on: what registration costs the avatar.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <regex>
#include <sstream>

#include "calibration/align.h"
#include "calibration/calibrate.h"
#include "calibration/evaluation.h"
#include "capture/ingest.h"
#include "capture/simulator.h"
#include "core/hash.h"
#include "core/json_io.h"
#include "core/log.h"
#include "core/parallel.h"
#include "core/paths.h"
#include "core/rotation.h"
#include "core/statistics.h"
#include "pipelines/bench_scene.h"
#include "pipelines/commands.h"
#include "pipelines/stage_table.h"
#include "reconstruction/track_evaluation.h"
#include "reconstruction/track_stage.h"

namespace headforge {

Status PrepareScene(const fs::path& scene_file, const fs::path& dir, const FaceModel& model, const std::string& data,
                    int threads, const std::string& crop, int identity_seed, bool simulated_masks,
                    IngestedCapture* capture, nlohmann::json* truth) {
  std::string text;
  HF_RETURN_IF_ERROR(ReadFileToString(scene_file, &text));
  if (identity_seed > 0) {
    const std::regex seed_line(R"(identity_seed\s*=\s*\d+)");
    if (!std::regex_search(text, seed_line))
      return Status::InvalidArgument(scene_file.string() + " has no identity_seed to vary");
    text = std::regex_replace(text, seed_line, "identity_seed = " + std::to_string(identity_seed));
  }
  // Simulation and ingest are redone when the scene, the crop or ingest's outputs change.
  Hasher hasher;
  hasher.Add(text).Add(crop).Add(int64_t(FindStage("ingest")->version));
  if (simulated_masks) hasher.Add(std::string("simulated masks"));
  const std::string stamp = hasher.Hex();
  std::string previous;
  if (!ReadFileToString(dir / "stamp", &previous).ok() || previous != stamp) {
    RemoveAll(dir);
    Scene scene;
    HF_RETURN_IF_ERROR(ParseScene(text, scene_file.string(), &scene));
    std::unique_ptr<Simulator> sim;
    HF_RETURN_IF_ERROR(Simulator::Create(scene, model, threads, &sim));
    StderrProgress progress;
    HF_RETURN_IF_ERROR(WriteSimulation(*sim, dir / "capture", text, 0, &progress));
    IngestOptions ingest;
    // A camera's frames: its image folder, or its video (a scene with video_compression).
    for (int c = 0; c < sim->num_cameras(); ++c) {
      const fs::path frames = dir / "capture" / sim->CameraName(c), video = frames.string() + ".mp4";
      ingest.inputs.push_back((fs::is_directory(frames) || !fs::exists(video) ? frames : video).string());
    }
    // The simulator's head masks, as a studio's matting gives them (a dome's
    // cameras behind the head see no face to mask from).
    if (simulated_masks) ingest.masks = (dir / "capture" / "masks").string();
    ingest.crop = crop;
    ingest.resolution = scene.camera.intrinsics.width;
    ingest.blur_ratio = 0.0;
    ResolveIngestDefaults(data, &ingest);
    IngestSummary summary;
    HF_RETURN_IF_ERROR(RunIngest(ingest, dir / "workspace", threads, &progress, &summary));
    HF_RETURN_IF_ERROR(WriteFileAtomic(dir / "stamp", stamp));
  }
  HF_RETURN_IF_ERROR(ReadIngestedCapture(dir / "workspace", capture));
  return ReadJson(dir / "capture" / "ground_truth.json", truth);
}

namespace {

struct Setting {
  std::string label;
  int max_features;
  std::string matcher;
  int frame_step;    // moving camera: every n-th frame
  int instants = 1;  // fixed rig: synchronised instants
  bool revisit = true;  // one video: match revisited views after the first model
  std::string camera_model = "SIMPLE_RADIAL";
  // Fixed rig: the simulator's own cameras as a rig file (calibrate --mode
  // rig) instead of COLMAP, so that the row measures align alone.
  bool rig_file = false;
  bool rig_in_metres = false;  // the file says its unit (metres_per_unit 1)
};

struct Row {
  std::string scene, label, mode;
  double seconds = 0;
  CameraErrors world, head;
  // When align's surface fit ran: on how many points, and the aligned
  // rotation error and scale error the landmarks alone gave (-1: no surface fit).
  int surface_points = 0;
  double landmarks_only_rotation_deg = -1, landmarks_only_scale_error = -1;
  bool ok = false;
  std::string error;
};

Row RunSetting(const std::string& scene, const Setting& s, const IngestedCapture& capture, const nlohmann::json& truth,
               const FaceModel& model, const fs::path& dir, int threads) {
  Row row;
  row.scene = scene;
  row.label = s.label;
  row.mode = s.rig_file ? "rig" : "colmap";
  CalibrateOptions options;
  options.mode = row.mode;
  if (s.rig_file) {
    // The rig file a studio's calibration would give: every camera's
    // intrinsics and its pose at the first instant (docs/calibration.md).
    nlohmann::json rig = {{"cameras", nlohmann::json::array()}};
    try {
      for (const auto& c : truth.at("cameras")) {
        nlohmann::json camera;
        for (const char* key : {"name", "width", "height", "fx", "fy", "cx", "cy", "k1", "k2"}) camera[key] = c.at(key);
        camera["cam_from_world"] = truth.at("frames").at(0).at("views").at(c.at("name").get<std::string>()).at("cam_from_world");
        rig["cameras"].push_back(camera);
      }
    } catch (const nlohmann::json::exception& e) {
      row.error = std::string("the ground truth has no rig to write: ") + e.what();
      return row;
    }
    if (s.rig_in_metres) rig["metres_per_unit"] = 1.0;
    std::error_code ec;
    fs::create_directories(dir, ec);
    options.rig = (dir / "rig.json").string();
    if (Status written = WriteJsonAtomic(options.rig, rig); !written.ok()) {
      row.error = written.message();
      return row;
    }
  }
  options.colmap.executable = DefaultColmapExecutable();
  options.colmap.max_features = s.max_features;
  options.colmap.matcher = s.matcher;
  options.colmap.frame_step = s.frame_step;
  options.colmap.rig_instants = s.instants;
  options.colmap.threads = threads;
  if (!s.revisit) options.colmap.revisit_angle_deg = 0;
  options.colmap.camera_model = s.camera_model;
  const auto start = std::chrono::steady_clock::now();
  CameraSet cameras;
  CalibrateSummary summary;
  NullProgress progress;
  Status status = RunCalibrate(options, capture, model, dir, &progress, &cameras, &summary);
  AlignResult aligned;
  // A rig's surface fit is not the pipeline's default (align.h); the table
  // shows it beside the landmarks' frame (the last column).
  AlignOptions align;
  align.rig_surface = true;
  if (status.ok()) status = RunAlign(align, capture, cameras, model, &aligned);
  row.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (status.ok()) status = EvaluateWorldCameras(cameras, capture, truth, &aligned.head_from_world, &row.world);
  // Several cameras watching a moving head: align's head frame is the head
  // at its reference instant, so it is scored there; at the other instants
  // the head has moved (track's head motion follows it).
  auto at_reference = [&aligned](CameraSet scored) {
    if (aligned.reference_frame >= 0)
      scored.views.erase(std::remove_if(scored.views.begin(), scored.views.end(),
                                        [&](const CameraView& v) { return v.frame != aligned.reference_frame; }),
                         scored.views.end());
    return scored;
  };
  if (status.ok()) status = EvaluateHeadCameras(at_reference(aligned.cameras), capture, truth, &row.head);
  if (status.ok() && aligned.surface_points > 0) {
    // What the surface fit bought: the landmarks' head frame, before the fit.
    CameraErrors head, world;
    const CameraSet landmarks_only = at_reference(ToHeadFrame(cameras, aligned.landmarks_head_from_world));
    status = EvaluateHeadCameras(landmarks_only, capture, truth, &head);
    if (status.ok()) status = EvaluateWorldCameras(cameras, capture, truth, &aligned.landmarks_head_from_world, &world);
    row.surface_points = aligned.surface_points;
    row.landmarks_only_rotation_deg = head.median_rotation_deg;
    row.landmarks_only_scale_error = world.scale_error;
  }
  // Registration counts the images COLMAP was given (fixed rigs: one per camera and instant).
  if (summary.sequential_registered >= 0)
    row.label += " (sequential registered " + std::to_string(summary.sequential_registered) +
                 (summary.keyframe_step > 0 ? ", then keyframes" : ", then every pair") + ")";
  else if (summary.revisit_pairs > 0)
    row.label += " (" + std::to_string(summary.revisit_pairs) + " revisit pairs)";
  row.world.registered = summary.registered;
  row.world.views = summary.total;
  row.ok = status.ok();
  row.error = status.message();
  return row;
}

// Head-pose cameras; `focal` > 0 gives the true focal length instead of
// estimating it; `mesh_weight` > 0 refines with the face mesh at that weight.
Row RunHeadPose(const std::string& scene, const IngestedCapture& capture, const nlohmann::json& truth,
                const FaceModel& model, const fs::path& dir, double focal, double mesh_weight = 0.0) {
  Row row;
  row.scene = scene;
  row.label = focal > 0 ? "head-pose, true focal given" : "head-pose, focal estimated";
  if (mesh_weight > 0) {
    std::ostringstream weight;
    weight << mesh_weight;
    row.label += ", face mesh " + weight.str();
  }
  row.mode = "head-pose";
  CalibrateOptions options;
  options.mode = "head-pose";
  options.head_pose.focal = focal;
  options.head_pose.refine_mesh_weight = mesh_weight;
  const auto start = std::chrono::steady_clock::now();
  CameraSet cameras;
  CalibrateSummary summary;
  NullProgress progress;
  Status status = RunCalibrate(options, capture, model, dir, &progress, &cameras, &summary);
  if (status.ok()) status = RefineHeadPoseStep(options, capture, model, 0, &progress, &cameras, &summary);
  row.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (status.ok()) status = EvaluateHeadCameras(cameras, capture, truth, &row.head);
  row.world = row.head;
  row.ok = status.ok();
  row.error = status.message();
  return row;
}

// How the simulated subject's face differs from the model's mean face, to
// which align fits: the similarity that best maps the mean face onto the
// subject's (the face region's vertices). Landmarks cannot see it (a bigger
// face looks like a nearer one; the identity modes include small tilts), so
// it bounds the scale and rotation align can reach on that subject.
struct SubjectOffset {
  bool ok = false;  // false: the truth's identity does not fit this model
  double scale = 1.0, rotation_deg = 0.0;
};

SubjectOffset MeasureSubjectOffset(const FaceModel& model, const nlohmann::json& truth) {
  SubjectOffset out;
  const auto& coefficients = truth.at("identity");
  if (coefficients.size() > static_cast<size_t>(model.num_identity())) return out;
  Eigen::VectorXf alpha(coefficients.size());
  for (size_t k = 0; k < coefficients.size(); ++k) alpha[k] = coefficients[k].get<float>();
  const Eigen::Matrix3Xf subject = model.Identity(alpha), mean = model.Identity(Eigen::VectorXf::Zero(alpha.size()));
  std::vector<int> vertices;
  if (const FaceModel::Region* face = model.FindRegion("face"))
    for (int v = face->first_vertex; v <= face->last_vertex; ++v) vertices.push_back(v);
  if (vertices.empty())
    for (int v = 0; v < model.num_vertices(); ++v) vertices.push_back(v);
  Eigen::Matrix3Xd src(3, vertices.size()), tgt(3, vertices.size());
  for (size_t k = 0; k < vertices.size(); ++k) {
    src.col(k) = mean.col(vertices[k]).cast<double>();
    tgt.col(k) = subject.col(vertices[k]).cast<double>();
  }
  const SimilarityResult fit = EstimateSimilarity(src, tgt);
  if (!fit.ok) return out;
  out.ok = true;
  out.scale = fit.tgt_from_src.scale;
  out.rotation_deg = Eigen::AngleAxisd(fit.tgt_from_src.rotation).angle() * 180.0 / 3.14159265358979323846;
  return out;
}

nlohmann::json RowJson(const Row& r) {
  return {{"scene", r.scene},
          {"setting", r.label},
          {"mode", r.mode},
          {"ok", r.ok},
          {"error", r.error},
          {"seconds", r.seconds},
          {"registered", r.world.registered},
          {"frames", r.world.views},
          {"rotation_deg_median", r.world.median_rotation_deg},
          {"rotation_deg_max", r.world.max_rotation_deg},
          {"centre_mm_median", r.world.median_centre_mm},
          {"centre_mm_max", r.world.max_centre_mm},
          {"scale_error", r.world.scale_error},
          {"focal_error", r.world.focal_error},
          {"aligned_rotation_deg_median", r.head.median_rotation_deg},
          {"aligned_centre_mm_median", r.head.median_centre_mm},
          {"surface_points", r.surface_points},
          {"aligned_rotation_deg_median_landmarks_only", r.landmarks_only_rotation_deg},
          {"scale_error_landmarks_only", r.landmarks_only_scale_error}};
}

void PrintRow(const Row& r) {
  if (!r.ok) {
    std::printf("| %s | %s | %.0f s | failed: %s |\n", r.scene.c_str(), r.label.c_str(), r.seconds, r.error.c_str());
    return;
  }
  char surface[96] = "-";
  if (r.surface_points > 0)
    std::snprintf(surface, sizeof(surface), "%.2f / %.2f%% (%d points)", r.landmarks_only_rotation_deg,
                  100 * r.landmarks_only_scale_error, r.surface_points);
  std::printf("| %s | %s | %.0f s | %d/%d | %.3f / %.3f | %.2f / %.2f | %.2f%% | %.2f%% | %.2f | %.1f | %s |\n",
              r.scene.c_str(), r.label.c_str(), r.seconds, r.world.registered, r.world.views,
              r.world.median_rotation_deg, r.world.max_rotation_deg, r.world.median_centre_mm, r.world.max_centre_mm,
              100 * r.world.scale_error, 100 * r.world.focal_error, r.head.median_rotation_deg,
              r.head.median_centre_mm, surface);
  std::fflush(stdout);
}

void PrintCalibrateHeader() {
  std::printf("| scene | setting | wall time | registered | rotation error median / max (deg) | centre error median / "
              "max (mm) | align scale error | focal error | aligned rotation (deg) | aligned centre (mm) | aligned "
              "rotation / scale error without the surface fit |\n");
  std::printf("(a rig's aligned rotation and centre: its cameras at align's reference instant, the head moving "
              "between instants)\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|\n");
}

// The settings to run on `scene` (`rig`: a fixed rig, else one moving camera).
std::vector<Setting> CalibrateSettings(const std::string& scene, bool rig, bool quick, const std::vector<int>& instants) {
  std::vector<Setting> settings;
  // The rig's own calibration first: what align alone leaves.
  if (rig) {
    settings.push_back({"rig file (the simulator's cameras)", 4096, "exhaustive", 1, 1, true, "SIMPLE_RADIAL", true});
    settings.push_back({"rig file in metres (metres_per_unit 1)", 4096, "exhaustive", 1, 1, true, "SIMPLE_RADIAL", true,
                        true});
  }
  if (rig && !instants.empty()) {
    for (int n : instants)
      settings.push_back({"4k SIFT, exhaustive, " + std::to_string(n) + (n == 1 ? " instant" : " instants"), 4096,
                          "exhaustive", 1, n});
  } else if (rig) {
    settings.push_back({"4k SIFT, exhaustive, 1 instant", 4096, "exhaustive", 1, 1});
    if (!quick) {
      settings.push_back({"1k SIFT", 1024, "exhaustive", 1, 1});
      settings.push_back({"8k SIFT", 8192, "exhaustive", 1, 1});
      settings.push_back({"sequential matching", 4096, "sequential", 1, 1});
      settings.push_back({"3 instants", 4096, "exhaustive", 1, 3});
      settings.push_back({"6 instants", 4096, "exhaustive", 1, 6});
    }
  } else {
    settings.push_back({"4k SIFT, sequential, every frame", 4096, "sequential", 1});
    // orbit_360_lit (the same orbit with shading) shows what lighting changes: the baseline only.
    if (!quick && scene != "orbit_360_lit") {
      settings.push_back({"no revisit matching", 4096, "sequential", 1, 1, false});
      // The scene's lens has no distortion: what knowing that buys.
      settings.push_back({"pinhole camera (SIMPLE_PINHOLE)", 4096, "sequential", 1, 1, true, "SIMPLE_PINHOLE"});
      settings.push_back({"1k SIFT", 1024, "sequential", 1});
      settings.push_back({"8k SIFT", 8192, "sequential", 1});
      settings.push_back({"exhaustive matching", 4096, "exhaustive", 1});
      settings.push_back({"every 2nd frame", 4096, "sequential", 2});
      settings.push_back({"every 4th frame", 4096, "sequential", 4});
    }
  }
  return settings;
}

// Each setting `repeat` times on `scene`, a row each (printed as it comes
// unless `json`), in dir/runs/<the setting's label>[_run<N>].
void RunSettings(const std::string& scene, const std::vector<Setting>& settings, int repeat,
                 const IngestedCapture& capture, const nlohmann::json& truth, const FaceModel& model,
                 const fs::path& dir, int threads, bool json, std::vector<Row>* results) {
  for (const auto& setting : settings) {
    for (int run = 1; run <= repeat; ++run) {
      Setting s = setting;
      std::string name = s.label;
      for (char& c : name)
        if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
      if (repeat > 1) {
        s.label += " (run " + std::to_string(run) + " of " + std::to_string(repeat) + ")";
        name += "_run" + std::to_string(run);
      }
      results->push_back(RunSetting(scene, s, capture, truth, model, dir / "runs" / name, threads));
      if (!json) PrintRow(results->back());
    }
  }
}

void PrintSubjectOffsets(const std::vector<std::pair<std::string, SubjectOffset>>& offsets) {
  std::printf("\n| scene | subject's face size / the mean face's | subject's face tilt against the mean face |\n");
  std::printf("|---|---|---|\n");
  for (const auto& [scene, o] : offsets)
    if (o.ok)
      std::printf("| %s | %.3f | %.2f deg |\n", scene.c_str(), o.scale, o.rotation_deg);
    else
      std::printf("| %s | n/a (the simulated identity does not fit this face model) | |\n", scene.c_str());
}

int BenchCalibrate(const std::vector<std::string>& args) {
  OptionSet options;
  CommonOptions common;
  AddCommonOptions(&options, &common, false);
  bool json = false, quick = false;
  std::string out = "bench_calibrate";
  std::vector<std::string> scenes = {"orbit_360", "orbit_360_lit", "rig_8cam", "talking_static"};
  options.Add("bench.json", &json, "Print one JSON document instead of the table.", "json");
  options.Add("bench.out", &out, "Folder for the simulated scenes, workspaces and COLMAP runs (reused).", "out");
  options.Add("bench.scenes", &scenes, "Scenes to run (from scenes/).", "scenes");
  options.Add("bench.quick", &quick, "Only the baseline setting of each scene.", "quick");
  bool masks = false;
  options.Add("bench.masks", &masks,
              "Ingest with the simulator's head masks (as a studio's matting gives them; dome_360 needs them: its "
              "cameras behind the head see no face to mask from).",
              "masks");
  std::vector<int> instants;
  options.Add("bench.rig_instants", &instants,
              "Fixed rigs: run only the baseline setting at each of these numbers of synchronised instants "
              "(e.g. 1,3) instead of the settings list.",
              "rig-instants");
  std::vector<double> mesh_weights;
  options.Add("bench.head_pose_mesh_weight", &mesh_weights,
              "talking_static: a head-pose row more for each weight, the face mesh's 468 points joining calibrate's "
              "face-model refinement at that weight against 1 for each of the 68 landmarks (default: none).",
              "head-pose-mesh-weight");
  int repeat = 1;
  options.Add("bench.repeat", &repeat,
              "Run each COLMAP setting this many times (COLMAP's results vary from run to run); one row per run.",
              "repeat");
  const int parsed = ParseOrExit(&options, args, "headforge bench calibrate [--json] [--out DIR] [--quick] [--masks] [--rig-instants N,M] [--repeat N]",
                                 "Runs calibrate and align on simulated scenes at several settings and prints, per\n"
                                 "setting: wall time, registered frames, rotation and camera-centre errors after the\n"
                                 "best similarity to the truth, the scale error of align, the focal error, and the\n"
                                 "errors of the aligned head-frame cameras (with and without align's surface fit).\n"
                                 "Fixed rigs first get a row with the simulator's own cameras as a rig file\n"
                                 "(calibrate --mode rig): the error align alone leaves.\n"
                                 "Without --quick, orbit_360 also runs with two more random subjects.\n"
                                 "The rows are kept in OUT/results.json; with --out WORKSPACE/bench_calibrate the\n"
                                 "workspace's report shows them.");
  if (parsed >= 0) return parsed;
  if (repeat < 1) return ReportFailure(Status::InvalidArgument("--repeat must be at least 1"));
  for (int n : instants)
    if (n < 1) return ReportFailure(Status::InvalidArgument("--rig-instants: " + std::to_string(n) + " is not at least 1"));
  ApplyCommonOptions(common);
  if (json) SetLogLevel(LogLevel::kWarning);
  const StageSettings settings = common.Settings();
  const int threads = settings.threads;
  FaceModel model;
  if (Status s = FaceModel::Load(settings.face_model, &model); !s.ok()) return ReportFailure(s);
  const fs::path scene_dir = fs::path(HEADFORGE_SOURCE_DIR) / "scenes";
  if (!json) PrintCalibrateHeader();
  nlohmann::json rows = nlohmann::json::array();
  std::vector<std::pair<std::string, SubjectOffset>> offsets;
  for (const auto& scene : scenes) {
    IngestedCapture capture;
    nlohmann::json truth;
    const fs::path dir = fs::path(out) / scene;
    const std::string crop = scene == "talking_static" ? "sequence" : "none";
    if (Status s = PrepareScene(scene_dir / (scene + ".toml"), dir, model, common.data_dir, threads, crop, 0, masks, &capture,
                                &truth);
        !s.ok())
      return ReportFailure(s.WithContext(scene));
    offsets.emplace_back(scene, MeasureSubjectOffset(model, truth));
    // The same scene with another random subject, in out/<scene>_identity_<seed>.
    struct Variant {
      std::string label;
      fs::path dir;
      IngestedCapture capture;
      nlohmann::json truth;
    };
    auto prepare_variant = [&](int seed, Variant* v) {
      v->label = scene + " (identity seed " + std::to_string(seed) + ")";
      v->dir = fs::path(out) / (scene + "_identity_" + std::to_string(seed));
      const Status s = PrepareScene(scene_dir / (scene + ".toml"), v->dir, model, common.data_dir, threads, crop, seed, masks,
                                    &v->capture, &v->truth);
      if (s.ok()) offsets.emplace_back(v->label, MeasureSubjectOffset(model, v->truth));
      return s.WithContext(v->label);
    };
    std::vector<Row> results;
    if (scene == "talking_static") {
      results.push_back(RunHeadPose(scene, capture, truth, model, dir / "runs" / "head_pose", 0.0));
      for (double w : mesh_weights)
        if (w > 0) results.push_back(RunHeadPose(scene, capture, truth, model, dir / "runs" / "head_pose_mesh", 0.0, w));
      const double true_focal = truth["cameras"][0]["fx"].get<double>() * capture.cameras[0].crop_scale;
      results.push_back(RunHeadPose(scene, capture, truth, model, dir / "runs" / "head_pose_known", true_focal));
      // The focal length from landmarks depends on how the subject's face
      // differs from the mean face: the same scene with other random subjects.
      for (int seed : quick ? std::vector<int>{} : std::vector<int>{12, 23, 47}) {
        Variant v;
        if (Status s = prepare_variant(seed, &v); !s.ok()) return ReportFailure(s);
        results.push_back(RunHeadPose(v.label, v.capture, v.truth, model, v.dir / "runs" / "head_pose", 0.0));
        for (double w : mesh_weights)
          if (w > 0)
            results.push_back(RunHeadPose(v.label, v.capture, v.truth, model, v.dir / "runs" / "head_pose_mesh", 0.0, w));
      }
    } else {
      const bool rig = capture.cameras.size() > 1;
      const std::vector<Setting> settings = CalibrateSettings(scene, rig, quick, instants);
      RunSettings(scene, settings, repeat, capture, truth, model, dir, threads, json, &results);
      // align's head frame depends on how the subject's face differs from the
      // mean face: the baseline setting with other random subjects.
      for (int seed : quick || scene != "orbit_360" ? std::vector<int>{} : std::vector<int>{5, 9}) {
        Variant v;
        if (Status s = prepare_variant(seed, &v); !s.ok()) return ReportFailure(s);
        results.push_back(RunSetting(v.label, settings.front(), v.capture, v.truth, model,
                                     v.dir / "runs" / "baseline", threads));
        if (!json) PrintRow(results.back());
      }
    }
    for (const auto& r : results) {
      if (!json && scene == "talking_static") PrintRow(r);
      rows.push_back(RowJson(r));
    }
  }
  nlohmann::json subjects = nlohmann::json::array();
  for (const auto& [scene, o] : offsets)
    if (o.ok) subjects.push_back({{"scene", scene}, {"face_scale", o.scale}, {"face_rotation_deg", o.rotation_deg}});
  // Kept for the report (export's --bench-results; a workspace's
  // bench_calibrate/results.json is read by default).
  const nlohmann::json results = {{"version", 1}, {"bench", "calibrate"}, {"settings", rows}, {"subjects", subjects}};
  if (Status s = WriteJsonAtomic(fs::path(out) / "results.json", results, 1); !s.ok()) return ReportFailure(s);
  if (json) {
    std::printf("%s\n", nlohmann::json{{"settings", rows}, {"subjects", subjects}}.dump(1).c_str());
  } else {
    PrintSubjectOffsets(offsets);
  }
  return kExitOk;
}

const std::vector<std::string> kScoredBlendshapes = {"jawOpen", "eyeBlink_L", "eyeBlink_R", "mouthSmile_L",
                                                     "mouthSmile_R"};

int BenchTrack(const std::vector<std::string>& args) {
  OptionSet options;
  CommonOptions common;
  AddCommonOptions(&options, &common, false);
  bool json = false;
  std::string out = "bench_track";
  std::vector<int> seeds = {11, 3, 7, 19, 27, 31, 42, 50};
  options.Add("bench.json", &json, "Print one JSON document instead of the table.", "json");
  options.Add("bench.out", &out, "Folder for the simulated captures and workspaces (reused).", "out");
  options.Add("bench.seeds", &seeds, "Identity seeds of the subjects (11 is talking_static's own).", "seeds");
  std::string scene = "talking_static";
  options.Add("bench.scene", &scene,
              "The scene (scenes/NAME.toml) of one camera before a moving head: talking_static, head_turn, "
              "talking_static_busy.",
              "scene");
  bool features = true;
  options.Add("bench.head_pose_features", &features,
              "Calibrate's head poses refined by features on the head's rigid part (false: from the landmarks alone, "
              "calibrate before version 3).",
              "head-pose-features");
  double mesh_weight = 0.4;
  options.Add("bench.mesh_weight", &mesh_weight,
              "A third row per subject: the identity columns and the face mesh at this weight (track's --mesh-weight); "
              "0 leaves it out.",
              "mesh-weight");
  const int parsed = ParseOrExit(&options, args, "headforge bench track [--json] [--out DIR] [--seeds A,B,...] [--scene NAME]",
                                 "Simulates talking_static (or --scene) with each subject, calibrates head-pose cameras and tracks\n"
                                 "it with the plain landmark points and with the points' identity columns, and\n"
                                 "prints per subject and points: landmark residual, head rotation error (also after\n"
                                 "one constant rotation of the head frame, and that rotation), blendshape MAE.\n"
                                 "The rows are kept in OUT/results.json; with --out WORKSPACE/bench_track the\n"
                                 "workspace's report shows them.");
  if (parsed >= 0) return parsed;
  if (seeds.empty()) return ReportFailure(Status::InvalidArgument("--seeds names no subject"));
  ApplyCommonOptions(common);
  if (json) SetLogLevel(LogLevel::kWarning);
  const StageSettings settings = common.Settings();
  const int threads = settings.threads;
  FaceModel model;
  if (Status s = FaceModel::Load(settings.face_model, &model); !s.ok()) return ReportFailure(s);
  const fs::path scene_file = fs::path(HEADFORGE_SOURCE_DIR) / "scenes" / (scene + ".toml");
  if (!fs::exists(scene_file)) return ReportFailure(Status::NotFound("no scene " + scene_file.string()));
  std::vector<std::pair<std::string, std::string>> embeddings = {{"plain", DefaultLandmarkEmbedding()},
                                                                 {"identity columns", IdentityLandmarkEmbedding()}};
  if (mesh_weight > 0) embeddings.push_back({"identity columns and the face mesh", IdentityLandmarkEmbedding()});
  if (!json) {
    std::printf("| subject | landmark points | residual (px) | head rotation (deg) | after one constant rotation (deg) "
                "| that rotation: pitch / yaw / roll (deg) | jawOpen | eyeBlink L / R | mouthSmile L / R | track time |\n");
    std::printf("|---|---|---|---|---|---|---|---|---|---|\n");
  }
  nlohmann::json rows = nlohmann::json::array();
  std::map<std::string, std::vector<double>> rotations;
  for (int seed : seeds) {
    const std::string subject = "identity seed " + std::to_string(seed);
    const fs::path dir = fs::path(out) / (scene + "_identity_" + std::to_string(seed));
    IngestedCapture capture;
    nlohmann::json truth;
    if (Status s = PrepareScene(scene_file, dir, model, common.data_dir, threads, "sequence", seed, false, &capture, &truth);
        !s.ok())
      return ReportFailure(s.WithContext(subject));
    CalibrateOptions calibrate;
    calibrate.mode = "head-pose";
    calibrate.head_pose.features = features;
    CameraSet cameras;
    CalibrateSummary calibrated;
    NullProgress progress;
    Status status = RunCalibrate(calibrate, capture, model, dir / "runs" / "head_pose", &progress, &cameras, &calibrated);
    if (status.ok()) status = RefineHeadPoseStep(calibrate, capture, model, 0, &progress, &cameras, &calibrated);
    if (!status.ok()) return ReportFailure(status.WithContext(subject + ": calibrate"));
    for (const auto& [label, file] : embeddings) {
      TrackStageOptions track;
      track.overlay = false;
      track.landmark_embedding = file;
      const bool with_mesh = label.find("mesh") != std::string::npos;
      track.fit.mesh_weight = with_mesh ? mesh_weight : 0.0;
      if (!with_mesh) track.mesh_embedding.clear();
      const fs::path track_dir =
          dir / "runs" / (label == "plain" ? "track_plain" : with_mesh ? "track_mesh" : "track_identity");
      TrackingErrors score;
      TrackSummary summary;
      const auto start = std::chrono::steady_clock::now();
      Status s = EnsureDirectory(track_dir);
      if (s.ok()) s = RunTrack(track, capture, cameras, model, track_dir, &progress, &summary);
      const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      TrackingFile tracking;
      if (s.ok()) s = ReadTracking(track_dir / "tracking.json", &tracking);
      if (s.ok()) s = EvaluateTracking(tracking, cameras, capture, truth, kScoredBlendshapes, &score);
      nlohmann::json row = {{"subject", subject}, {"points", label}, {"ok", s.ok()}, {"error", s.message()},
                            {"seconds", seconds}};
      if (s.ok()) {
        rotations[label].push_back(score.rotation_deg);
        row.update({{"residual_px", score.residual_px},
                    {"rotation_deg", score.rotation_deg},
                    {"rotation_after_constant_deg", score.motion_deg},
                    {"constant_rotation_deg", {score.constant_deg.x(), score.constant_deg.y(), score.constant_deg.z()}},
                    {"blendshape_mae", score.mae}});
      }
      rows.push_back(row);
      if (json) continue;
      if (!s.ok()) {
        std::printf("| %s | %s | failed: %s |\n", subject.c_str(), label.c_str(), s.message().c_str());
      } else {
        std::printf("| %s | %s | %.2f | %.2f | %.2f | %+.2f / %+.2f / %+.2f | %.3f | %.3f / %.3f | %.3f / %.3f | %.0f s |\n",
                    subject.c_str(), label.c_str(), score.residual_px, score.rotation_deg, score.motion_deg,
                    score.constant_deg.x(), score.constant_deg.y(), score.constant_deg.z(), score.mae["jawOpen"],
                    score.mae["eyeBlink_L"], score.mae["eyeBlink_R"], score.mae["mouthSmile_L"],
                    score.mae["mouthSmile_R"], seconds);
      }
      std::fflush(stdout);
    }
  }
  const nlohmann::json results = {{"version", 1}, {"bench", "track"}, {"tracks", rows}};
  if (Status s = WriteJsonAtomic(fs::path(out) / "results.json", results, 1); !s.ok()) return ReportFailure(s);
  if (json) {
    std::printf("%s\n", nlohmann::json{{"tracks", rows}}.dump(1).c_str());
  } else {
    std::printf("\n| landmark points | head rotation over the subjects: median / mean / worst (deg) |\n|---|---|\n");
    for (const auto& [label, file] : embeddings) {
      const auto& r = rotations[label];
      if (r.empty()) continue;
      double mean = 0;
      for (double x : r) mean += x / r.size();
      std::printf("| %s | %.2f / %.2f / %.2f |\n", label.c_str(), Median(r), mean, *std::max_element(r.begin(), r.end()));
    }
  }
  return kExitOk;
}

}  // namespace

int BenchTruthWorkspace(const std::vector<std::string>& args) {
  OptionSet options;
  CommonOptions common;
  AddCommonOptions(&options, &common, /*with_workspace=*/true);
  std::string truth_dir, out;
  std::vector<std::string> parts = {"cameras", "expression", "identity"};
  options.Add("bench.truth", &truth_dir, "The simulated capture the workspace was ingested from (its ground_truth.json).",
              "truth");
  options.Add("bench.out", &out, "The new workspace (made, or replaced when an earlier truth-workspace made it).", "out");
  options.Add("bench.replace", &parts,
              "What the truth replaces: cameras (intrinsics and every view's pose), expression, identity.", "replace");
  const int parsed = ParseOrExit(
      &options, args, "headforge bench truth-workspace --workspace WS --truth SIM --out DIR [--replace cameras,expression,identity]",
      "Copies a tracked workspace of a simulated capture (frames, masks, landmarks) to DIR with\n"
      "the simulator's truth in place of what calibrate and track estimated: train or bench\n"
      "train on DIR to see what the registration error costs the avatar. The simulator's own\n"
      "masks: ingest with --masks SIM/masks. Prints how far the tracked values were from the truth.");
  if (parsed >= 0) return parsed;
  if (Status s = common.Check(true); !s.ok()) return ReportFailure(s);
  if (truth_dir.empty()) return ReportFailure(Status::InvalidArgument("no --truth: give the simulated capture's folder"));
  if (out.empty()) return ReportFailure(Status::InvalidArgument("no --out: give the new workspace's folder"));
  ApplyCommonOptions(common);
  parts = SplitCommaList(parts);
  const fs::path ws(common.workspace), to(out);
  const fs::path marker = to / "truth_workspace.json";
  std::error_code ec;
  if (fs::equivalent(ws, to, ec)) return ReportFailure(Status::InvalidArgument("--out is the workspace itself"));
  if (fs::exists(to) && !fs::is_empty(to, ec) && !fs::exists(marker))
    return ReportFailure(Status::InvalidArgument(
        "--out " + out + " holds files bench truth-workspace did not write; name a new folder"));
  if (Status s = CheckTrackedWorkspace(common.workspace, /*with_model=*/false, "bench truth-workspace"); !s.ok())
    return ReportFailure(s);
  FaceModel model;
  if (Status s = FaceModel::Load(common.Settings().face_model, &model); !s.ok()) return ReportFailure(s);
  IngestedCapture capture;
  CameraSet cameras;
  TrackingFile tracking;
  if (Status s = ReadTrackedWorkspace(ws, model, &capture, &cameras, &tracking); !s.ok()) return ReportFailure(s);
  nlohmann::json truth;
  if (Status s = ReadJson(fs::path(truth_dir) / "ground_truth.json", &truth); !s.ok())
    return ReportFailure(s.WithContext("--truth " + truth_dir + " (a headforge simulate output)"));
  TrackingErrors before;
  const Status scored = EvaluateTracking(tracking, cameras, capture, truth, kScoredBlendshapes, &before);
  const CameraSet tracked_cameras = cameras;
  const std::set<std::string> part_set(parts.begin(), parts.end());
  if (Status s = TruthAsTracked(capture, truth, part_set, &cameras, &tracking); !s.ok()) return ReportFailure(s);
  Status s = RemoveAll(to);
  if (s.ok()) s = EnsureDirectory(to);
  for (const char* name : {"capture.json", "landmarks.json", "frames", "masks"}) {
    if (!s.ok()) break;
    fs::copy(ws / name, to / name, fs::copy_options::recursive, ec);
    if (ec) s = Status::IoError("cannot copy " + (ws / name).string() + " to " + to.string() + ": " + ec.message());
  }
  if (s.ok()) s = cameras.Write(to / "cameras_head.json");
  if (s.ok()) s = WriteTracking(tracking, to / "tracking.json");
  if (s.ok()) s = WriteJsonAtomic(marker, {{"workspace", fs::absolute(ws).string()},
                                           {"truth", fs::absolute(truth_dir).string()},
                                           {"replaced", parts}}, 1);
  if (!s.ok()) return ReportFailure(s.WithContext("bench truth-workspace"));
  std::string replaced;
  for (const std::string& p : parts) replaced += (replaced.empty() ? "" : ", ") + p;
  std::printf("%s: the workspace with the truth's %s\n", out.c_str(), replaced.c_str());
  if (scored.ok()) {
    std::printf("the tracked values against the truth: head rotation %.2f deg (median), jawOpen MAE %.3f",
                before.rotation_deg, before.mae["jawOpen"]);
    for (const CameraIntrinsics& c : tracked_cameras.cameras)
      if (const CameraIntrinsics* t = cameras.FindCamera(c.name); t && t->fx > 0)
        std::printf(", %s focal %.1f px against %.1f px (%+.1f%%)", c.name.c_str(), c.fx, t->fx, 100 * (c.fx / t->fx - 1));
    std::printf("\n");
  }
  return kExitOk;
}

int BenchCommand(const std::vector<std::string>& args) {
  if (!args.empty() && args[0] == "calibrate") return BenchCalibrate(std::vector<std::string>(args.begin() + 1, args.end()));
  if (!args.empty() && args[0] == "track") return BenchTrack(std::vector<std::string>(args.begin() + 1, args.end()));
  if (!args.empty() && args[0] == "train") return BenchTrain(std::vector<std::string>(args.begin() + 1, args.end()));
  if (!args.empty() && args[0] == "front-end")
    return BenchFrontEnd(std::vector<std::string>(args.begin() + 1, args.end()));
  if (!args.empty() && args[0] == "drive") return BenchDrive(std::vector<std::string>(args.begin() + 1, args.end()));
  if (!args.empty() && args[0] == "truth-workspace")
    return BenchTruthWorkspace(std::vector<std::string>(args.begin() + 1, args.end()));
  std::fprintf(stderr,
               "Usage: headforge bench calibrate|track|train|front-end|drive|truth-workspace [options]\n"
               "  calibrate   camera accuracy against time on simulated scenes\n"
               "  front-end   ingest's masks (and their cost) against the simulator's truth\n"
               "  track       tracking accuracy over many simulated subjects\n"
               "  train       the avatar's ablation on a tracked workspace\n"
               "  drive       cross-identity driving: the avatar driven by other workspaces, per\n"
               "              remedy of the driver's weights (F-LMD, CSIM)\n"
               "  truth-workspace  a simulated capture's workspace with the true cameras and\n"
               "              tracking, to train on (what registration costs the avatar)\n"
               "(rendering and kernel speed: build/bench/headforge_bench)\n");
  return args.empty() || args[0] == "--help" ? (args.empty() ? kExitUsage : kExitOk) : kExitUsage;
}

}  // namespace headforge
