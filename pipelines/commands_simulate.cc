// `headforge simulate`: renders a scene file into a capture with ground truth.
#include <algorithm>

#include "calibration/landmark_embedding.h"
#include "calibration/mesh_embedding.h"
#include "capture/simulator.h"
#include "core/paths.h"
#include "core/log.h"
#include "core/parallel.h"
#include "pipelines/commands.h"
#include "reconstruction/landmark_basis.h"

namespace headforge {

int SimulateCommand(const std::vector<std::string>& args) {
  OptionSet options;
  CommonOptions common;
  AddCommonOptions(&options, &common, /*with_workspace=*/false);
  std::string scene_path, out_dir;
  int frames = 0;
  options.Add("simulate.scene", &scene_path, "Scene file (TOML); see scenes/ and docs/simulator.md.", "scene");
  options.Add("simulate.out", &out_dir, "Output folder: one image folder (or video) per camera, masks/, ground_truth.json.",
              "out");
  options.Add("simulate.frames", &frames, "Render only the first N frames; 0 renders the scene's whole duration.",
              "frames");
  const std::string usage = "headforge simulate --scene FILE --out DIR [--frames N]";
  const int parsed = ParseOrExit(&options, args, usage,
                                 "Renders a synthetic head capture with ground truth (cameras, head pose, expressions,\n"
                                 "landmarks), simulating only the effects the scene lists.");
  if (parsed >= 0) return parsed;
  if (Status s = common.Check(false); !s.ok()) return ReportFailure(s);
  if (scene_path.empty()) return ReportFailure(Status::InvalidArgument("give the scene file with --scene"));
  if (out_dir.empty()) return ReportFailure(Status::InvalidArgument("give the output folder with --out"));
  if (frames < 0) return ReportFailure(Status::InvalidArgument("--frames must be >= 0"));
  const StageSettings settings = common.Settings();
  ApplyCommonOptions(common);

  std::string text;
  if (Status s = ReadFileToString(scene_path, &text).WithContext("scene"); !s.ok()) return ReportFailure(s);
  Scene scene;
  if (Status s = ParseScene(text, scene_path, &scene); !s.ok()) return ReportFailure(s);
  FaceModel model;
  if (Status s = FaceModel::Load(settings.face_model, &model); !s.ok()) return ReportFailure(s);
  std::unique_ptr<Simulator> simulator;
  const int threads = settings.threads;
  if (Status s = Simulator::Create(scene, model, threads, &simulator); !s.ok()) return ReportFailure(s);
  HF_LOG(Info) << "simulate: " << scene.name << ", " << simulator->num_cameras() << " camera(s) x "
               << (frames > 0 ? std::min(frames, simulator->num_frames()) : simulator->num_frames())
               << " frames, effects: "
               << (scene.effects.empty() ? std::string("none") : [&] {
                    std::string all;
                    for (const auto& e : scene.effects) all += (all.empty() ? "" : ", ") + e;
                    return all;
                  }());
  StderrProgress progress;
  if (Status s = WriteSimulation(*simulator, out_dir, text, frames, &progress); !s.ok()) return ReportFailure(s);
  HF_LOG(Info) << "simulate: wrote " << out_dir;
  return kExitOk;
}

int EmbedLandmarksCommand(const std::vector<std::string>& args) {
  OptionSet options;
  CommonOptions common;
  AddCommonOptions(&options, &common, /*with_workspace=*/false);
  std::string out;
  options.Add("embed.out", &out,
              "Where to write the embedding (JSON); default: the shipped file's name in the current folder "
              "(ict_dlib68_landmark_embedding.json or, with --views or --identity, ..._views.json or "
              "..._identity.json). The shipped file in data/ is replaced only when --out names it.",
              "out");
  bool views = false;
  options.Add("embed.views", &views,
              "Also measure the points from each direction of the camera (yaw -60..60, pitch -20..20 degrees), "
              "which track uses view by view (400 more renders).",
              "views");
  bool identity = false;
  int subjects = 40;
  options.Add("embed.identity", &identity,
              "Instead, measure how the points move with the subject's identity: random subjects (varied face, skin "
              "and light) are measured one by one (60 renders each) and the points' identity columns fitted; track "
              "uses them with one camera.",
              "identity");
  options.Add("embed.subjects", &subjects, "Subjects measured with --identity (at least 10).", "subjects");
  bool mesh = false;
  std::string vision_models = DefaultVisionModelsDir();
  options.Add("embed.mesh", &mesh,
              "Instead, measure where MediaPipe's face mesh (468 points, ingest's --face-mesh) sits on the face model "
              "(120 renders); default file ict_facemesh468_embedding.json, which calibrate and track read.",
              "mesh");
  options.Add("embed.vision_models", &vision_models, "Folder of the face mesh's model (facemesh.json).",
              "vision-models");
  const int parsed = ParseOrExit(&options, args, "headforge embed-landmarks [--out FILE] [--views | --identity | --mesh]",
                                 "Measures where the landmark detector's 68 points sit on the face model, from\n"
                                 "simulator renders of the mean face (calibration/landmark_embedding.h).");
  if (parsed >= 0) return parsed;
  const StageSettings settings = common.Settings();
  ApplyCommonOptions(common);
  FaceModel model;
  if (Status s = FaceModel::Load(settings.face_model, &model); !s.ok()) return ReportFailure(s);
  FaceDetectorOptions detector;
  detector.ultraface_dir = (fs::path(common.data_dir) / "models" / "ultraface").string();
  const int threads = settings.threads;
  if (int(views) + int(identity) + int(mesh) > 1)
    return ReportFailure(
        Status::InvalidArgument("embed-landmarks: --views, --identity and --mesh measure different files; give one"));
  const std::string shipped = views      ? ViewLandmarkEmbedding()
                              : identity ? IdentityLandmarkEmbedding()
                              : mesh     ? DefaultMeshEmbedding()
                                         : DefaultLandmarkEmbedding();
  // A measurement lands beside the user, not over the file that calibrate,
  // align and track read by default: replacing that is a deliberate --out.
  if (out.empty()) out = fs::path(shipped).filename().string();
  if (mesh) {
    std::vector<Eigen::Vector3d> points;
    MeshEmbeddingReport report;
    if (Status s = MeasureMeshEmbedding(model, detector, DefaultLandmarkModel(), vision_models, threads, &points,
                                        &report);
        !s.ok())
      return ReportFailure(s);
    if (Status s = WriteMeshEmbedding(out, points); !s.ok()) return ReportFailure(s);
    char line[256];
    std::snprintf(line, sizeof(line),
                  "embed-landmarks: the face mesh on %d renders, %d of 468 points on the head; a point's renders lie "
                  "%.2f mm from its median (median over the points)",
                  report.renders, report.points_seen, 1e3 * report.median_spread);
    HF_LOG(Info) << line;
  } else if (identity) {
    LandmarkEmbedding embedding;
    IdentityFitReport report;
    if (Status s = MeasureIdentityLandmarkEmbedding(model, detector, DefaultLandmarkModel(), threads, subjects,
                                                    &embedding, &report);
        !s.ok())
      return ReportFailure(s);
    if (Status s = WriteLandmarkEmbedding(out, embedding); !s.ok()) return ReportFailure(s);
    char line[256];
    std::snprintf(line, sizeof(line),
                  "embed-landmarks: %d subjects; a held-out subject's points predicted within %.2f mm (median), "
                  "%.2f mm when they ride on the surface (ridge weight %.0f)",
                  report.subjects, 1e3 * report.loo_median, 1e3 * report.loo_median_surface, report.lambda);
    HF_LOG(Info) << line;
  } else if (views) {
    LandmarkEmbedding embedding;
    if (Status s = MeasureViewLandmarkEmbedding(model, detector, DefaultLandmarkModel(), threads, &embedding); !s.ok())
      return ReportFailure(s);
    if (Status s = WriteLandmarkEmbedding(out, embedding); !s.ok()) return ReportFailure(s);
  } else {
    std::vector<Eigen::Vector3d> points;
    if (Status s = MeasureLandmarkEmbedding(model, detector, DefaultLandmarkModel(), threads, &points); !s.ok())
      return ReportFailure(s);
    if (Status s = WriteLandmarkEmbedding(out, points); !s.ok()) return ReportFailure(s);
  }
  HF_LOG(Info) << "embed-landmarks: wrote " << out;
  std::error_code ec;
  if (!fs::equivalent(out, shipped, ec))
    HF_LOG(Info) << "embed-landmarks: the stages use it when given it: "
                 << (views      ? "track --track-landmark-embedding " + out + " (views that surround the head)"
                     : identity ? "track --track-landmark-embedding " + out + " (one camera)"
                     : mesh     ? "calibrate and track --mesh-embedding " + out
                                : "calibrate --landmark-embedding " + out + ", align --align-landmark-embedding " + out);
  return kExitOk;
}

}  // namespace headforge
