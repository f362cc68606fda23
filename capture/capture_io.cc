#include "capture/capture_io.h"

#include <cstdio>
#include <nlohmann/json.hpp>

#include "core/json_io.h"

namespace headforge {

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

Status ReadIngestedCapture(const fs::path& workspace, IngestedCapture* capture) {
  nlohmann::json cj, lj;
  const fs::path capture_path = workspace / "capture.json";
  if (!fs::exists(capture_path))
    return Status::NotFound("no ingest outputs in " + workspace.string() + " (run headforge ingest first)");
  HF_RETURN_IF_ERROR(ReadJson(capture_path, &cj));
  HF_RETURN_IF_ERROR(ReadJson(workspace / "landmarks.json", &lj));
  IngestedCapture out;
  out.workspace = workspace;
  try {
    out.fps = cj.at("fps").get<double>();
    const int resolution = cj.at("resolution").get<int>();
    for (const auto& c : cj.at("cameras")) {
      IngestedCamera cam;
      cam.name = c.at("name").get<std::string>();
      cam.source = c.at("source").get<std::string>();
      cam.source_width = c.at("source_size")[0].get<int>();
      cam.source_height = c.at("source_size")[1].get<int>();
      cam.fixed_crop = c.contains("crop");
      if (cam.fixed_crop) {
        const auto& crop = c.at("crop");
        cam.crop_x0 = crop.at("x0").get<double>();
        cam.crop_y0 = crop.at("y0").get<double>();
        cam.crop_scale = crop.at("scale").get<double>();
        cam.width = crop.at("output")[0].get<int>();
        cam.height = crop.at("output")[1].get<int>();
      } else {
        cam.width = cam.height = resolution;
      }
      const auto& lm = lj.at("cameras").at(cam.name);
      for (const auto& f : c.at("frames")) {
        IngestedFrame frame;
        frame.index = f.at("index").get<int>();
        frame.source_frame = f.at("source_frame").get<int>();
        frame.time_s = f.at("time_s").get<double>();
        const auto& l = lm.at(frame.index);
        if (l.at("found").get<bool>()) {
          Landmarks68 points;
          for (int i = 0; i < 68; ++i)
            points[i] = cv::Point2f(l.at("points")[i][0].get<float>(), l.at("points")[i][1].get<float>());
          frame.landmarks = points;
          frame.score = l.value("score", 0.0);
        }
        cam.frames.push_back(frame);
      }
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
