#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <nlohmann/json.hpp>

#include "capture/simulator.h"
#include "core/image_io.h"
#include "core/json_io.h"

namespace headforge {
namespace {

std::string FrameName(int frame) {
  char name[32];
  std::snprintf(name, sizeof(name), "%06d.png", frame);
  return name;
}

double Round(double v, double step) { return std::round(v / step) * step; }

Status EncodeVideo(const fs::path& frames, const fs::path& video, double fps, int crf) {
  if (std::system("command -v ffmpeg >/dev/null 2>&1") != 0)
    return Status::NotFound("video_compression needs the ffmpeg program (Debian package ffmpeg)");
  const std::string command = "ffmpeg -y -loglevel error -framerate " + std::to_string(fps) + " -i '" +
                              (frames / "%06d.png").string() + "' -c:v libx264 -crf " + std::to_string(crf) +
                              " -pix_fmt yuv420p -vf 'pad=ceil(iw/2)*2:ceil(ih/2)*2' '" + video.string() + "'";
  if (std::system(command.c_str()) != 0) return Status::IoError("ffmpeg failed to encode " + video.string());
  return Status::Ok();
}

}  // namespace

Status WriteSimulation(const Simulator& sim, const fs::path& out_dir, const std::string& scene_text,
                       int max_frames, Progress* progress) {
  const Scene& scene = sim.scene();
  const FaceModel& model = sim.model();
  HF_RETURN_IF_ERROR(EnsureDirectory(out_dir));
  const bool compress = scene.HasEffect("video_compression");

  nlohmann::json effects = nlohmann::json::array();
  for (const auto& name : KnownEffects()) {
    if (!scene.HasEffect(name)) continue;
    nlohmann::json params = nlohmann::json::object();
    const auto it = scene.effect_params.find(name);
    if (it != scene.effect_params.end())
      for (const auto& [k, v] : it->second) params[k] = v;
    effects.push_back({{"name", name}, {"params", params}});
  }
  nlohmann::json cameras = nlohmann::json::array();
  const int frame_count = max_frames > 0 ? std::min(max_frames, sim.num_frames()) : sim.num_frames();
  std::vector<nlohmann::json> frames(frame_count);
  const int total = frame_count * sim.num_cameras();
  progress->Start("simulate " + scene.name, total);
  for (int c = 0; c < sim.num_cameras(); ++c) {
    const std::string name = sim.CameraName(c);
    const fs::path frame_dir = compress ? out_dir / ".encode" / name : out_dir / name;
    HF_RETURN_IF_ERROR(RemoveAll(frame_dir));
    double k1 = 0, k2 = 0;
    for (int f = 0; f < frame_count; ++f) {
      const SimulatedView view = sim.RenderView(f, c);
      k1 = view.k1;
      k2 = view.k2;
      HF_RETURN_IF_ERROR(WriteImageAtomic(frame_dir / FrameName(f), view.image));
      HF_RETURN_IF_ERROR(WriteImageAtomic(out_dir / "masks" / name / FrameName(f), view.mask));
      nlohmann::json& frame = frames[f];
      if (c == 0) {
        const SubjectState state = sim.StateAt(sim.FrameTime(f));
        nlohmann::json expression = nlohmann::json::object();
        for (int e = 0; e < model.num_expressions(); ++e)
          expression[model.expression_names()[e]] = Round(state.expression[e], 1e-6);
        frame = {{"index", f},
                 {"time_s", sim.FrameTime(f)},
                 {"world_from_head", PoseToJson(state.world_from_head)},
                 {"expression", expression},
                 {"views", nlohmann::json::object()}};
      }
      nlohmann::json landmarks = nlohmann::json::array(), visible = nlohmann::json::array(),
                     depth = nlohmann::json::array();
      for (int i = 0; i < 68; ++i) {
        landmarks.push_back({Round(view.landmarks[i].x(), 1e-4), Round(view.landmarks[i].y(), 1e-4)});
        visible.push_back(static_cast<bool>(view.visible[i]));
        depth.push_back(Round(view.depth[i], 1e-6));
      }
      frame["views"][name] = {{"cam_from_world", PoseToJson(view.camera.cam_from_world)},
                              {"landmarks", landmarks},
                              {"visible", visible},
                              {"landmark_depth", depth}};
      progress->Advance();
    }
    if (compress) {
      const int crf = static_cast<int>(scene.Param("video_compression", "crf", 23));
      HF_RETURN_IF_ERROR(EncodeVideo(frame_dir, out_dir / (name + ".mp4"), scene.fps, crf));
      HF_RETURN_IF_ERROR(RemoveAll(frame_dir));
    }
    const PinholeCamera cam = sim.CameraAt(c, 0.0);
    cameras.push_back({{"name", name},
                       {"input", compress ? name + ".mp4" : name},
                       {"width", cam.width},
                       {"height", cam.height},
                       {"fx", cam.fx},
                       {"fy", cam.fy},
                       {"cx", cam.cx},
                       {"cy", cam.cy},
                       {"k1", k1},
                       {"k2", k2},
                       {"moving", scene.camera.rig == "orbit" || scene.camera.rig == "handheld"}});
  }
  if (compress) HF_RETURN_IF_ERROR(RemoveAll(out_dir / ".encode"));
  progress->Finish();

  std::vector<double> identity(sim.identity().data(), sim.identity().data() + sim.identity().size());
  const nlohmann::json truth = {
      {"scene", scene.name},
      {"fps", scene.fps},
      {"frame_count", frame_count},
      {"scene_frame_count", sim.num_frames()},
      {"conventions",
       "metres; head frame +y up, face toward +z; OpenCV cameras; pixel centres at integers; "
       "landmarks in iBUG-68 order, distorted when lens_distortion is applied"},
      {"face_model", model.path()},
      {"identity", identity},
      {"effects", effects},
      {"cameras", cameras},
      {"frames", frames}};
  HF_RETURN_IF_ERROR(WriteJsonAtomic(out_dir / "ground_truth.json", truth, -1));
  if (!scene_text.empty()) HF_RETURN_IF_ERROR(WriteFileAtomic(out_dir / "scene.toml", scene_text));
  return Status::Ok();
}

}  // namespace headforge
