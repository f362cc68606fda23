#include "capture/capture_io.h"

#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>

#include "core/json_io.h"

namespace headforge {
namespace {

nlohmann::json CropJson(const CropWindow& c) {
  return {{"x0", c.x0}, {"y0", c.y0}, {"width", c.width}, {"height", c.height},
          {"scale", c.scale}, {"output", {c.output.width, c.output.height}}};
}

CropWindow CropFromJson(const nlohmann::json& j) {
  CropWindow c;
  c.x0 = j.at("x0").get<double>();
  c.y0 = j.at("y0").get<double>();
  c.width = j.at("width").get<double>();
  c.height = j.at("height").get<double>();
  c.scale = j.at("scale").get<double>();
  c.output = cv::Size(j.at("output")[0].get<int>(), j.at("output")[1].get<int>());
  return c;
}

nlohmann::json CameraJson(const IngestedCapture& capture, const IngestedCamera& cam) {
  nlohmann::json frames = nlohmann::json::array();
  for (const IngestedFrame& f : cam.frames) {
    nlohmann::json frame = {{"index", f.index},
                            {"source_frame", f.source_frame},
                            {"time_s", f.time_s},
                            {"sharpness", f.sharpness},
                            {"face", f.landmarks ? "found" : "lost"}};
    if (!f.source_file.empty()) frame["source_file"] = f.source_file;
    if (f.crop) frame["crop"] = CropJson(*f.crop);
    frames.push_back(frame);
  }
  nlohmann::json json = {{"name", cam.name},
                         {"source", cam.source},
                         {"source_fps", cam.source_fps},
                         {"source_size", {cam.source_width, cam.source_height}},
                         {"offset", cam.offset},
                         {"median_sharpness", cam.median_sharpness},
                         {"masks", cam.masks},
                         {"frames", frames}};
  if (cam.decoder_errors > 0) {
    json["decoder_errors"] = cam.decoder_errors;
    json["decoder_error"] = cam.decoder_error;
  }
  if (cam.fixed_crop) {
    CropWindow crop;
    crop.x0 = cam.crop_x0;
    crop.y0 = cam.crop_y0;
    crop.width = cam.crop_width;
    crop.height = cam.crop_height;
    crop.scale = cam.crop_scale;
    crop.output = cv::Size(cam.width, cam.height);
    json["crop"] = CropJson(crop);
  }
  return json;
}

nlohmann::json LandmarksJson(const IngestedCamera& cam) {
  nlohmann::json frames = nlohmann::json::array();
  for (const IngestedFrame& f : cam.frames) {
    nlohmann::json entry = {{"index", f.index}, {"found", f.landmarks.has_value()}};
    if (f.landmarks) {
      nlohmann::json points = nlohmann::json::array();
      for (const auto& p : *f.landmarks) points.push_back({p.x, p.y});
      entry["score"] = f.score;
      entry["detector"] = f.detector;
      entry["box"] = {f.box.x, f.box.y, f.box.width, f.box.height};
      entry["points"] = points;
    }
    if (!f.mesh.empty()) {
      nlohmann::json mesh = nlohmann::json::array();
      for (const cv::Point3f& p : f.mesh)
        for (float v : {p.x, p.y, p.z}) mesh.push_back(std::round(v * 100.0f) / 100.0f);
      entry["mesh"] = mesh;
      entry["mesh_score"] = std::round(f.mesh_score * 1000.0f) / 1000.0f;
    }
    frames.push_back(entry);
  }
  return frames;
}

}  // namespace

std::string FrameFileName(int index) {
  char name[32];
  std::snprintf(name, sizeof(name), "%06d.png", index);
  return name;
}

fs::path IngestedCapture::FramePath(const std::string& camera, int index) const {
  return workspace / "frames" / camera / FrameFileName(index);
}

fs::path IngestedCapture::MaskPath(const std::string& camera, int index) const {
  return workspace / "masks" / camera / FrameFileName(index);
}

const IngestedCamera* IngestedCapture::FindCamera(const std::string& name) const {
  for (const IngestedCamera& c : cameras)
    if (c.name == name) return &c;
  return nullptr;
}

const IngestedFrame* IngestedCapture::FindFrame(const std::string& camera, int index) const {
  const IngestedCamera* c = FindCamera(camera);
  if (c == nullptr) return nullptr;
  for (const IngestedFrame& f : c->frames)
    if (f.index == index) return &f;
  return nullptr;
}

Status WriteIngestedCapture(const IngestedCapture& capture, const fs::path& dir) {
  nlohmann::json landmarks = {{"version", IngestedCapture::kVersion},
                              {"format", "ibug68"},
                              {"mesh_format", "MediaPipe face mesh where found: 468 points as x, y (frame pixels) "
                                              "and z (relative depth, frame pixels, nearer smaller), flattened"},
                              {"coordinates", "pixels of frames/<camera>/<index>.png, pixel centres at integers"},
                              {"cameras", nlohmann::json::object()}};
  nlohmann::json cameras = nlohmann::json::array();
  for (const IngestedCamera& cam : capture.cameras) {
    if (cam.frames.size() != capture.samples.size())
      return Status::Internal("capture.json: camera " + cam.name + " has " + std::to_string(cam.frames.size()) +
                              " frames for " + std::to_string(capture.samples.size()) + " samples");
    landmarks["cameras"][cam.name] = LandmarksJson(cam);
    cameras.push_back(CameraJson(capture, cam));
  }
  nlohmann::json frames = nlohmann::json::array();
  for (size_t i = 0; i < capture.samples.size(); ++i) {
    const double time_s = capture.cameras.empty() ? 0.0 : capture.cameras[0].frames[i].time_s;
    frames.push_back({{"index", i}, {"sample", capture.samples[i]}, {"time_s", time_s}});
  }
  nlohmann::json dropped = nlohmann::json::array();
  for (const DroppedSample& d : capture.dropped)
    dropped.push_back({{"sample", d.sample}, {"source_frames", d.source_frames}, {"reason", d.reason},
                       {"detail", d.detail}});
  const IngestCounts& n = capture.counts;
  const nlohmann::json json = {
      {"version", IngestedCapture::kVersion},
      {"crop_mode", capture.crop_mode},
      {"crop_mapping", "u_out = (u_src + 0.5 - x0) * scale - 0.5, pixel centres at integers"},
      {"fps", capture.fps},
      {"resolution", capture.resolution},
      {"frames", frames},
      {"cameras", cameras},
      {"dropped", dropped},
      {"report",
       {{"sampled", n.sampled},
        {"kept", n.kept},
        {"dropped_blur", n.dropped_blur},
        {"dropped_missing", n.dropped_missing},
        {"face_lost", n.face_lost},
        {"with_landmarks", n.with_landmarks}}}};
  HF_RETURN_IF_ERROR(WriteJsonAtomic(dir / "landmarks.json", landmarks, -1));
  return WriteJsonAtomic(dir / "capture.json", json, 1);
}

Status ReadIngestedCapture(const fs::path& workspace, IngestedCapture* capture) {
  nlohmann::json cj, lj;
  HF_RETURN_IF_ERROR(ReadArtefact(workspace / "capture.json", IngestedCapture::kVersion, "ingest", &cj));
  HF_RETURN_IF_ERROR(ReadArtefact(workspace / "landmarks.json", IngestedCapture::kVersion, "ingest", &lj));
  IngestedCapture out;
  out.workspace = workspace;
  try {
    out.fps = cj.at("fps").get<double>();
    out.resolution = cj.at("resolution").get<int>();
    out.crop_mode = cj.at("crop_mode").get<std::string>();
    for (const auto& f : cj.at("frames")) out.samples.push_back(f.at("sample").get<int>());
    for (const auto& d : cj.at("dropped")) {
      out.dropped.push_back({d.at("sample").get<int>(), d.at("source_frames").get<std::map<std::string, int64_t>>(),
                             d.at("reason").get<std::string>(), d.at("detail").get<std::string>()});
    }
    const auto& report = cj.at("report");
    out.counts = {report.at("sampled").get<int>(),         report.at("kept").get<int>(),
                  report.at("dropped_blur").get<int>(),    report.at("dropped_missing").get<int>(),
                  report.at("face_lost").get<int>(),       report.at("with_landmarks").get<int>()};
    for (const auto& c : cj.at("cameras")) {
      IngestedCamera cam;
      cam.name = c.at("name").get<std::string>();
      cam.source = c.at("source").get<std::string>();
      cam.source_fps = c.at("source_fps").get<double>();
      cam.offset = c.at("offset").get<int>();
      cam.median_sharpness = c.at("median_sharpness").get<double>();
      cam.decoder_errors = c.value("decoder_errors", 0);
      cam.decoder_error = c.value("decoder_error", std::string());
      cam.masks = c.at("masks").get<std::string>();
      cam.source_width = c.at("source_size")[0].get<int>();
      cam.source_height = c.at("source_size")[1].get<int>();
      cam.fixed_crop = c.contains("crop");
      if (cam.fixed_crop) {
        const CropWindow crop = CropFromJson(c.at("crop"));
        cam.crop_x0 = crop.x0;
        cam.crop_y0 = crop.y0;
        cam.crop_width = crop.width;
        cam.crop_height = crop.height;
        cam.crop_scale = crop.scale;
        cam.width = crop.output.width;
        cam.height = crop.output.height;
      } else {
        cam.width = cam.height = out.resolution;
      }
      const auto& lm = lj.at("cameras").at(cam.name);
      for (const auto& f : c.at("frames")) {
        IngestedFrame frame;
        frame.index = f.at("index").get<int>();
        frame.source_frame = f.at("source_frame").get<int>();
        frame.time_s = f.at("time_s").get<double>();
        frame.sharpness = f.at("sharpness").get<double>();
        frame.source_file = f.value("source_file", "");
        if (f.contains("crop")) frame.crop = CropFromJson(f.at("crop"));
        const auto& l = lm.at(frame.index);
        if (l.at("found").get<bool>()) {
          Landmarks68 points;
          for (int i = 0; i < 68; ++i)
            points[i] = cv::Point2f(l.at("points")[i][0].get<float>(), l.at("points")[i][1].get<float>());
          frame.landmarks = points;
          frame.score = l.at("score").get<double>();
          frame.detector = l.at("detector").get<std::string>();
          const auto& box = l.at("box");
          frame.box = cv::Rect2f(box[0].get<float>(), box[1].get<float>(), box[2].get<float>(), box[3].get<float>());
        }
        if (l.contains("mesh")) {
          const auto& mesh = l.at("mesh");
          if (mesh.size() % 3 != 0)
            return Status::DataError("landmarks.json: a face mesh of " + std::to_string(mesh.size()) + " numbers");
          for (size_t i = 0; i + 2 < mesh.size(); i += 3)
            frame.mesh.emplace_back(mesh[i].get<float>(), mesh[i + 1].get<float>(), mesh[i + 2].get<float>());
          frame.mesh_score = l.value("mesh_score", 0.0f);
        }
        cam.frames.push_back(frame);
      }
      if (cam.frames.size() != out.samples.size())
        return Status::DataError("ingest outputs in " + workspace.string() + " are damaged: camera " + cam.name +
                                 " lists " + std::to_string(cam.frames.size()) + " frames of " +
                                 std::to_string(out.samples.size()) + "; run headforge ingest again");
      out.cameras.push_back(std::move(cam));
    }
  } catch (const nlohmann::json::exception& e) {
    return Status::DataError("ingest outputs in " + workspace.string() + " are damaged: " + e.what() +
                             "; run headforge ingest again");
  }
  *capture = std::move(out);
  return Status::Ok();
}

}  // namespace headforge
