#include "export/drive_page.h"

#include <cmath>
#include <cstdint>
#include <cstring>

#include <nlohmann/json.hpp>

#include "calibration/mesh_embedding.h"
#include "avatar/train/dataset_options.h"
#include "capture/capture_io.h"
#include "core/camera_set.h"
#include "core/face_model.h"
#include "core/json_io.h"
#include "export/html_util.h"
#include "export/web_scripts.h"
#include "reconstruction/landmark_basis.h"
#include "reconstruction/tracking_io.h"

namespace headforge {
namespace {

// IEEE 754 binary16, rounded to nearest even.
uint16_t ToHalf(float value) {
  uint32_t bits;
  std::memcpy(&bits, &value, sizeof(bits));
  const uint16_t sign = uint16_t((bits >> 16) & 0x8000u);
  const int exponent = int((bits >> 23) & 0xff) - 127 + 15;
  uint32_t mantissa = bits & 0x7fffffu;
  if (((bits >> 23) & 0xff) == 0xff) return uint16_t(sign | 0x7c00u | (mantissa ? 0x200u : 0));
  if (exponent >= 31) return uint16_t(sign | 0x7c00u);
  if (exponent <= 0) {
    if (exponent < -10) return sign;
    mantissa |= 0x800000u;
    const int shift = 14 - exponent;
    uint32_t half = mantissa >> shift;
    const uint32_t rest = mantissa & ((1u << shift) - 1), midway = 1u << (shift - 1);
    if (rest > midway || (rest == midway && (half & 1u))) ++half;
    return uint16_t(sign | half);
  }
  uint32_t half = (uint32_t(exponent) << 10) | (mantissa >> 13);
  const uint32_t rest = mantissa & 0x1fffu;
  if (rest > 0x1000u || (rest == 0x1000u && (half & 1u))) ++half;  // may carry into the exponent: still right
  return uint16_t(sign | half);
}

std::vector<double> RowMajor3x4(const Eigen::Isometry3d& m) {
  std::vector<double> out;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 4; ++j) out.push_back(m.matrix()(i, j));
  return out;
}

// The blendshapes as the page reads them: opacities and neutral float32,
// the offsets float32 or float16.
Status ReadBlendshapeBytes(const fs::path& dir, bool half, nlohmann::json* layout, std::string* bytes) {
  HF_RETURN_IF_ERROR(ReadJson(dir / "blendshapes.json", layout));
  if (layout->value("format", "") != "headforge-gaussian-blendshapes")
    return Status::NotFound("drive: no Gaussian blendshapes in " + dir.string() +
                            " (export --formats blendshapes drive writes them first)");
  const int64_t n = layout->value("gaussians", int64_t(0));
  const int64_t k = int64_t(layout->value("expressions", std::vector<std::string>()).size());
  std::string raw;
  HF_RETURN_IF_ERROR(ReadFileToString(dir / "blendshapes.bin", &raw));
  const size_t head = sizeof(float) * size_t(n * 14), body = sizeof(float) * size_t(n * k * 13);
  if (n <= 0 || raw.size() != head + body)
    return Status::DataError("drive: " + dir.string() + "/blendshapes.bin holds " + std::to_string(raw.size()) +
                             " bytes where blendshapes.json lays out " + std::to_string(head + body) +
                             "; export them again (headforge export --formats blendshapes)");
  if (!half) {
    *bytes = std::move(raw);
    return Status::Ok();
  }
  bytes->assign(raw, 0, head);
  std::vector<uint16_t> halves(size_t(n * k * 13));
  for (size_t i = 0; i < halves.size(); ++i) {
    float v;
    std::memcpy(&v, raw.data() + head + sizeof(float) * i, sizeof(float));
    halves[i] = ToHalf(v);
  }
  bytes->append(reinterpret_cast<const char*>(halves.data()), halves.size() * sizeof(uint16_t));
  return Status::Ok();
}

// The face mesh's 468 points for the tracked subject: at every expression
// weight 0, and each weight's offsets (head frame, metres).
Status FaceBasis(const DrivePageOptions& options, const TrackingFile& tracking, nlohmann::json* basis) {
  FaceModel model;
  HF_RETURN_IF_ERROR(FaceModel::Load(options.face_model, &model));
  std::vector<Eigen::Vector3d> points;
  const std::string embedding = options.mesh_embedding.empty() ? DefaultMeshEmbedding() : options.mesh_embedding;
  HF_RETURN_IF_ERROR(ReadMeshEmbedding(embedding, &points).WithContext("drive"));
  LandmarkBasis landmarks;
  HF_RETURN_IF_ERROR(BuildLandmarkBasis(model, points, tracking.identity_modes, &landmarks));
  if (landmarks.num_expressions != int(tracking.expression_names.size()))
    return Status::DataError("drive: the face model has " + std::to_string(landmarks.num_expressions) +
                             " expressions, the tracking " + std::to_string(tracking.expression_names.size()));
  nlohmann::json neutral = nlohmann::json::array(), offsets = nlohmann::json::array();
  const Eigen::VectorXd none;
  for (int i = 0; i < landmarks.size(); ++i) {
    const Eigen::Vector3d p = landmarks.Point(i, tracking.identity, none);
    neutral.push_back({p.x(), p.y(), p.z()});
  }
  for (int e = 0; e < landmarks.num_expressions; ++e) {
    nlohmann::json shape = nlohmann::json::array();
    for (int i = 0; i < landmarks.size(); ++i) {
      const Eigen::Vector3d d = landmarks.expression[size_t(i)].col(e);
      shape.push_back({d.x(), d.y(), d.z()});
    }
    offsets.push_back(std::move(shape));
  }
  *basis = {{"format", "facemesh468 drive basis"},
            {"expression_names", tracking.expression_names},
            {"neutral", std::move(neutral)},
            {"offsets", std::move(offsets)},
            {"oval", MeshOvalPoints()}};
  return Status::Ok();
}

// The avatar's training frames' tracked weights, weight by weight: their
// mean and spread (standard deviation), the frames training held out left
// out as it split them (DatasetOptions' hold-out over the capture's frames).
// The page's solve pulls each weight toward the mean, the more the narrower
// its spread (face_drive.js, weightPull).
Status ExpressionPrior(const fs::path& workspace, const TrackingFile& tracking, const DatasetOptions& trained,
                       const CameraSet& cameras, nlohmann::json* prior) {
  IngestedCapture capture;
  HF_RETURN_IF_ERROR(ReadIngestedCapture(workspace, &capture).WithContext("drive"));
  const HoldoutSplit split = SplitFrames(capture.num_frames(), trained.holdout,
                                         HoldoutInterleaved(trained.holdout_order, cameras.WalksRoundTheHead()));
  const size_t k = tracking.expression_names.size();
  std::vector<double> sum(k, 0.0), squares(k, 0.0);
  int count = 0;
  for (const TrackedFrame& f : tracking.frames) {
    if (split.HeldOut(f.frame)) continue;
    for (size_t e = 0; e < k; ++e) {
      sum[e] += f.expression[Eigen::Index(e)];
      squares[e] += f.expression[Eigen::Index(e)] * f.expression[Eigen::Index(e)];
    }
    ++count;
  }
  if (count == 0) return Status::DataError("drive: no tracked frame of the avatar's training frames; run headforge track");
  std::vector<double> mean(k), spread(k);
  for (size_t e = 0; e < k; ++e) {
    mean[e] = sum[e] / count;
    spread[e] = std::sqrt(std::max(0.0, squares[e] / count - mean[e] * mean[e]));
  }
  *prior = {{"frames", count}, {"mean", mean}, {"spread", spread}};
  return Status::Ok();
}

}  // namespace

Status WriteDrivePage(const fs::path& out_dir, const DrivePageOptions& options, DrivePageSummary* summary) {
  nlohmann::json layout;
  std::string shapes;
  HF_RETURN_IF_ERROR(ReadBlendshapeBytes(options.blendshapes_dir, options.half_offsets, &layout, &shapes));
  TrackingFile tracking;
  HF_RETURN_IF_ERROR(ReadTracking(options.workspace / "tracking.json", &tracking));
  const std::vector<std::string> names = layout.value("expressions", std::vector<std::string>());
  if (names != tracking.expression_names)
    return Status::DataError("drive: the blendshapes' expressions are not the tracking's; export the blendshapes again");
  CameraSet cameras;
  HF_RETURN_IF_ERROR(CameraSet::Read(options.workspace / "cameras_head.json", &cameras));
  if (cameras.cameras.empty()) return Status::DataError("drive: cameras_head.json holds no camera; run headforge align");
  const CameraIntrinsics& lens = cameras.cameras.front();

  // The page draws through the capture's first camera at the avatar's
  // training size, as headforge render does; its take is that camera's
  // tracked frames.
  DatasetOptions trained;  // the avatar's data options, as render reads them
  FromJson(layout.value("data", nlohmann::json::object()), &trained);
  const double scale = double(trained.resolution) / std::max(lens.width, lens.height);
  const double fy = lens.fy > 0 ? lens.fy : lens.fx;
  const nlohmann::json page_camera = {{"fx", lens.fx * scale},
                                      {"fy", fy * scale},
                                      {"cx", (lens.cx + 0.5) * scale - 0.5},
                                      {"cy", (lens.cy + 0.5) * scale - 0.5},
                                      {"width", int(std::lround(lens.width * scale))},
                                      {"height", int(std::lround(lens.height * scale))}};
  nlohmann::json frames = nlohmann::json::array(), poses = nlohmann::json::array();
  for (const TrackedFrame& f : tracking.frames) {
    const CameraView* view = cameras.FindView(lens.name, f.frame);
    if (!view || !view->registered) continue;
    const std::vector<double> pose = RowMajor3x4(view->cam_from_world * f.head_motion);
    frames.push_back({{"frame", f.frame},
                      {"weights", std::vector<double>(f.expression.data(), f.expression.data() + f.expression.size())},
                      {"cam_from_head", pose}});
    poses.push_back({{"frame", f.frame}, {"cam_from_head", pose}});
  }

  nlohmann::json basis;
  HF_RETURN_IF_ERROR(FaceBasis(options, tracking, &basis));
  HF_RETURN_IF_ERROR(ExpressionPrior(options.workspace, tracking, trained, cameras, &basis["expression_prior"]));
  // The face mesh works in the capture's own pixels.
  basis["camera"] = {{"fx", lens.fx}, {"fy", fy}, {"cx", lens.cx}, {"cy", lens.cy},
                     {"width", lens.width}, {"height", lens.height}};
  nlohmann::json file_basis = basis;
  file_basis["frames"] = poses;  // for checks against the tracking
  HF_RETURN_IF_ERROR(EnsureDirectory(out_dir));
  HF_RETURN_IF_ERROR(WriteJsonAtomic(out_dir / "face_basis.json", file_basis, -1));

  std::string tfjs, mesh_json, mesh_bin;
  const bool webcam = !options.tfjs_js.empty() && ReadFileToString(options.tfjs_js, &tfjs).ok() &&
                      ReadFileToString(options.vision_models / "facemesh.json", &mesh_json).ok() &&
                      ReadFileToString(options.vision_models / "facemesh.bin", &mesh_bin).ok();
  std::string mesh, engine;
  const bool with_mesh = !options.mesh_glb.empty() && ReadFileToString(options.mesh_glb, &mesh).ok() &&
                         !options.playcanvas_js.empty() && ReadFileToString(options.playcanvas_js, &engine).ok();
  const int64_t n = layout.value("gaussians", int64_t(0));
  const nlohmann::json data = {{"names", names},
                               {"gaussians", n},
                               {"offsets_type", options.half_offsets ? "float16" : "float32"},
                               {"camera", page_camera},
                               {"background", 1.0},
                               {"fps", 25},
                               {"frames", frames},
                               {"face", webcam ? basis : nlohmann::json()}};
  std::string html = R"(<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>HeadForge avatar: drive</title>
<meta name="viewport" content="width=device-width, initial-scale=1">
<style>
html, body { margin: 0; height: 100%; background: #292b30; color: #ddd; font: 13px system-ui, sans-serif; }
#stage { display: flex; gap: 16px; padding: 12px; align-items: flex-start; }
#view, #mesh-view { max-height: calc(100vh - 24px); max-width: calc((100vw - 300px) / 2); }
#side { width: 260px; }
#side button, #side label { display: block; margin: 0 0 8px; }
.bar { position: relative; margin: 2px 0; padding: 1px 4px; }
.bar::before { content: ''; position: absolute; inset: 0; width: calc(var(--w) * 100%); background: #4a7bd0; opacity: 0.5; z-index: -1; }
#weights { position: relative; z-index: 0; }
</style>
</head><body>
<div id="stage"><canvas id="view"></canvas><canvas id="mesh-view" hidden></canvas><div id="side">
<button id="webcam">Drive from the webcam</button>
<button id="replay">Play the capture's take</button>
<label>Play a take (Live Link Face CSV or tracking.json) or drive from a video of a face: <input id="open" type="file" accept=".csv,.json,video/*"></label>
<div id="weights"></div></div></div>
)";
  html += "<script id=\"drive-data\" type=\"application/json\">" + InlineScriptText(data.dump()) + "</script>\n";
  html += "<script id=\"blendshapes\" type=\"application/octet-stream\">" + Base64(shapes) + "</script>\n";
  if (webcam) {
    html += "<script id=\"facemesh-json\" type=\"application/json\">" + InlineScriptText(mesh_json) + "</script>\n";
    html += "<script id=\"facemesh-bin\" type=\"application/octet-stream\">" + Base64(mesh_bin) + "</script>\n";
    html += "<script>" + InlineScriptText(tfjs) + "</script>\n";
  }
  if (with_mesh) {
    html += "<script id=\"mesh-glb\" type=\"application/octet-stream\">" + Base64(mesh) + "</script>\n";
    html += "<script>" + InlineScriptText(engine) + "</script>\n";
  }
  html += std::string("<script>") + InlineScriptText(kSplatGlScript) + "</script>\n";
  html += std::string("<script>") + InlineScriptText(kFaceDriveScript) + "</script>\n";
  html += std::string("<script>") + InlineScriptText(kDrivePageScript) + "</script>\n</body></html>\n";
  HF_RETURN_IF_ERROR(WriteFileAtomic(out_dir / "index.html", html));
  summary->webcam = webcam;
  summary->mesh = with_mesh;
  summary->gaussians = n;
  summary->page_bytes = int64_t(html.size());
  if (!webcam)
    summary->note = "the page plays takes only: TensorFlow.js (" + options.tfjs_js + ") or the face mesh model (" +
                    (options.vision_models / "facemesh.json").string() +
                    ") is missing; scripts/install_deps.sh installs both";
  return Status::Ok();
}

void AddDrivePageScripts(Hasher* hasher) {
  for (const char* script : {kSplatGlScript, kFaceDriveScript, kDrivePageScript}) hasher->Add(std::string(script));
}

}  // namespace headforge
