// `headforge bench front-end`: what ingest's masks are worth against the
// simulator's truth, and what they cost. Simulates each scene, ingests it
// once with the simulator's own masks (cropped as ingest crops, the truth)
// and once per matte (GrabCut, the learned networks), and prints per matte
// the masks' IoU with the truth (mean and worst frame), the network's
// milliseconds per frame alone and ingest's wall time.
#include <chrono>
#include <cstdio>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "capture/ingest.h"
#include "core/json_io.h"
#include "core/log.h"
#include "core/paths.h"
#include "pipelines/bench_scene.h"
#include "pipelines/commands.h"
#include "vision/face_mesh.h"
#include "vision/person_matte.h"

namespace headforge {
namespace {

struct MatteRow {
  std::string scene, matte;
  int frames = 0;
  double mean_iou = 0, min_iou = 1, network_ms = 0, ingest_s = 0;
  int worst_frame = -1;
  std::string error;
};

double Seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

// Mean and worst IoU of `ws`'s masks with `truth`'s, frame by frame.
Status CompareMasks(const IngestedCapture& truth, const fs::path& ws, MatteRow* row) {
  IngestedCapture got;
  HF_RETURN_IF_ERROR(ReadIngestedCapture(ws, &got));
  if (got.num_frames() != truth.num_frames())
    return Status::Internal("the matte's ingest kept " + std::to_string(got.num_frames()) + " frames, the truth's " +
                            std::to_string(truth.num_frames()));
  double sum = 0;
  for (const IngestedFrame& f : truth.cameras[0].frames) {
    const cv::Mat a = cv::imread(truth.MaskPath("cam0", f.index).string(), cv::IMREAD_GRAYSCALE) > 127;
    const cv::Mat b = cv::imread(got.MaskPath("cam0", f.index).string(), cv::IMREAD_GRAYSCALE) > 127;
    if (a.empty() || b.empty() || a.size() != b.size()) return Status::DataError("unreadable or mismatched masks");
    const double both = cv::countNonZero(a & b), either = cv::countNonZero(a | b);
    const double iou = either > 0 ? both / either : 1.0;
    sum += iou;
    if (iou < row->min_iou) row->min_iou = iou, row->worst_frame = f.index;
  }
  row->frames = truth.num_frames();
  row->mean_iou = sum / std::max(1, row->frames);
  return Status::Ok();
}

// The network alone on the truth workspace's frames, after one warm-up run.
Status TimeNetwork(const IngestedCapture& truth, const std::string& kind, const std::string& models, MatteRow* row) {
  std::unique_ptr<PersonMatte> matte;
  HF_RETURN_IF_ERROR(PersonMatte::Load(models, kind, &matte));
  const int n = std::min(20, truth.num_frames());
  std::vector<cv::Mat> frames;
  for (int i = 0; i < n; ++i) frames.push_back(cv::imread(truth.FramePath("cam0", truth.cameras[0].frames[i].index).string()));
  matte->Alpha(frames[0]);
  matte->Reset();
  const auto start = std::chrono::steady_clock::now();
  for (const cv::Mat& f : frames) matte->Alpha(f);
  row->network_ms = 1000.0 * Seconds(start) / n;
  return Status::Ok();
}

// The face mesh alone (its two passes, as ingest runs it) on the truth
// workspace's frames, after one warm-up run; milliseconds per frame.
Status TimeFaceMesh(const IngestedCapture& truth, const std::string& models, double* ms) {
  std::unique_ptr<FaceMesh> mesh;
  HF_RETURN_IF_ERROR(FaceMesh::Load(models, &mesh));
  std::vector<std::pair<cv::Mat, FaceRegion>> frames;
  for (const IngestedFrame& f : truth.cameras[0].frames) {
    if (!f.landmarks || frames.size() >= 20) continue;
    frames.emplace_back(cv::imread(truth.FramePath("cam0", f.index).string()),
                        FaceRegionFrom68(std::vector<cv::Point2f>(f.landmarks->begin(), f.landmarks->end())));
  }
  if (frames.empty()) return Status::DataError("no frame with landmarks to time the face mesh on");
  mesh->Refine(frames[0].first, frames[0].second);
  const auto start = std::chrono::steady_clock::now();
  for (const auto& [image, region] : frames) mesh->Refine(image, region);
  *ms = 1000.0 * Seconds(start) / frames.size();
  return Status::Ok();
}

}  // namespace

int BenchFrontEnd(const std::vector<std::string>& args) {
  OptionSet options;
  CommonOptions common;
  AddCommonOptions(&options, &common, false);
  bool json = false;
  std::string out = "bench_front_end";
  std::vector<std::string> scenes = {"talking_static"};
  std::vector<std::string> mattes = {"grabcut", "selfie", "meet", "rvm"};
  std::string models = DefaultVisionModelsDir();
  options.Add("bench.json", &json, "Print one JSON document instead of the table.", "json");
  options.Add("bench.out", &out, "Folder for the simulated scenes and workspaces (reused).", "out");
  options.Add("bench.scenes", &scenes, "Scenes to run (from scenes/).", "scenes");
  options.Add("bench.mattes", &mattes, "Mattes to compare (grabcut, selfie, meet, rvm).", "mattes");
  options.Add("bench.vision_models", &models, "Folder of the learned models' files.", "vision-models");
  const int parsed = ParseOrExit(&options, args, "headforge bench front-end [--json] [--out DIR] [--scenes A,B] [--mattes A,B]",
                                 "Simulates each scene, ingests it with the simulator's masks (the truth) and with\n"
                                 "each matte, and prints per matte: the masks' mean and worst IoU with the truth,\n"
                                 "the network's milliseconds per frame alone, and ingest's wall time. The rows are\n"
                                 "kept in OUT/front_end.json.");
  if (parsed >= 0) return parsed;
  ApplyCommonOptions(common);
  if (json) SetLogLevel(LogLevel::kWarning);
  const StageSettings settings = common.Settings();
  FaceModel model;
  if (Status s = FaceModel::Load(settings.face_model, &model); !s.ok()) return ReportFailure(s);
  const fs::path scene_dir = fs::path(HEADFORGE_SOURCE_DIR) / "scenes";
  if (!json) {
    std::printf("| scene | matte | frames | mean IoU with the truth | worst frame | network ms/frame | ingest s |\n");
    std::printf("|---|---|---|---|---|---|---|\n");
  }
  nlohmann::json rows = nlohmann::json::array();
  for (const std::string& scene : scenes) {
    const fs::path dir = fs::path(out) / scene;
    IngestedCapture truth;
    nlohmann::json ground;
    if (Status s = PrepareScene(scene_dir / (scene + ".toml"), dir, model, common.data_dir, settings.threads,
                                "sequence", 0, true, &truth, &ground);
        !s.ok())
      return ReportFailure(s.WithContext(scene));
    for (const std::string& matte : mattes) {
      MatteRow row;
      row.scene = scene;
      row.matte = matte;
      IngestOptions ingest;
      ingest.inputs = {(dir / "capture" / "cam0").string()};
      ingest.crop = "sequence";
      ingest.resolution = truth.resolution;
      ingest.blur_ratio = 0.0;
      ingest.matte = matte;
      ingest.vision_models = models;
      ResolveIngestDefaults(common.data_dir, &ingest);
      const fs::path ws = dir / ("matte_" + matte);
      RemoveAll(ws);
      IngestSummary summary;
      NullProgress progress;
      const auto start = std::chrono::steady_clock::now();
      Status s = RunIngest(ingest, ws, settings.threads, &progress, &summary);
      row.ingest_s = Seconds(start);
      if (s.ok() && summary.masks != matte) s = Status::DataError("ingest masked with " + summary.masks);
      if (s.ok()) s = CompareMasks(truth, ws, &row);
      if (s.ok() && matte != "grabcut") s = TimeNetwork(truth, matte, models, &row);
      if (!s.ok()) row.error = s.message();
      rows.push_back({{"scene", row.scene}, {"matte", row.matte}, {"frames", row.frames}, {"mean_iou", row.mean_iou},
                      {"min_iou", row.min_iou}, {"worst_frame", row.worst_frame}, {"network_ms", row.network_ms}, {"ingest_s", row.ingest_s},
                      {"error", row.error}});
      if (json) continue;
      if (!row.error.empty())
        std::printf("| %s | %s | failed: %s |||||\n", scene.c_str(), matte.c_str(), row.error.c_str());
      else
        std::printf("| %s | %s | %d | %.4f | %.4f (frame %d) | %s | %.1f |\n", scene.c_str(), matte.c_str(), row.frames,
                    row.mean_iou, row.min_iou, row.worst_frame, matte == "grabcut" ? "-" : std::to_string(int(row.network_ms + 0.5)).c_str(),
                    row.ingest_s);
      std::fflush(stdout);
    }
  }
  // The face mesh's cost, on the last scene's frames.
  double mesh_ms = 0;
  if (!scenes.empty()) {
    IngestedCapture truth;
    Status s = ReadIngestedCapture(fs::path(out) / scenes.back() / "workspace", &truth);
    if (s.ok()) s = TimeFaceMesh(truth, models, &mesh_ms);
    if (!s.ok()) return ReportFailure(s.WithContext("timing the face mesh"));
    if (!json) std::printf("\nface mesh (two passes per frame): %.0f ms per frame\n", mesh_ms);
  }
  const nlohmann::json doc = {
      {"bench", "front-end"}, {"threads", settings.threads}, {"rows", rows}, {"face_mesh_ms", mesh_ms}};
  if (Status s = WriteJsonAtomic(fs::path(out) / "front_end.json", doc); !s.ok()) return ReportFailure(s);
  if (json) std::printf("%s\n", doc.dump(1).c_str());
  return kExitOk;
}

}  // namespace headforge
