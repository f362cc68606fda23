#include "calibration/landmark_embedding.h"

#include <cmath>

#include "capture/landmarks.h"
#include "capture/simulator.h"
#include "core/json_io.h"
#include "core/log.h"

namespace headforge {

std::string DefaultLandmarkEmbedding() { return HEADFORGE_LANDMARK_EMBEDDING; }

Status MeasureLandmarkEmbedding(const FaceModel& model, const FaceDetectorOptions& detector,
                                const std::string& landmark_model, int threads, std::vector<Eigen::Vector3d>* points) {
  // The mean face, lit from the front, turning +-25 degrees and nodding +-12.
  const std::string scene_text =
      "name = \"landmark_embedding\"\nfps = 25\nframes = 60\neffects = [\"lighting\"]\n"
      "[subject]\nidentity = [0.0]\n[background]\ntype = \"flat\"\n"
      "[camera]\nposition = [0.0, 0.0, 0.65]\n[camera.intrinsics]\nwidth = 512\nheight = 512\nfocal = 1100.0\n"
      "[head]\nyaw = { type = \"sine\", amplitude = 25.0, period = 2.4 }\n"
      "pitch = { type = \"sine\", amplitude = 12.0, period = 1.1 }\n"
      "[effect.lighting]\nx = 0.4\ny = 0.5\nz = 0.9\nambient = 0.45\ndiffuse = 0.7\n";
  Scene scene;
  HF_RETURN_IF_ERROR(ParseScene(scene_text, "landmark embedding scene", &scene));
  std::unique_ptr<Simulator> sim;
  HF_RETURN_IF_ERROR(Simulator::Create(scene, model, threads, &sim));
  std::unique_ptr<FaceDetector> faces;
  HF_RETURN_IF_ERROR(FaceDetector::Create(detector, &faces));
  std::unique_ptr<LandmarkPredictor> predictor;
  HF_RETURN_IF_ERROR(LandmarkPredictor::Load(landmark_model, &predictor));
  std::vector<Eigen::Vector3d> sum(68, Eigen::Vector3d::Zero());
  std::vector<int> count(68, 0);
  for (int f = 0; f < sim->num_frames(); ++f) {
    const SimulatedView view = sim->RenderView(f, 0);
    const auto found = faces->Detect(view.image);
    if (found.empty()) continue;
    const Landmarks68 lm = predictor->Predict(view.image, found[0].landmark_box);
    const Eigen::Isometry3d head_from_cam =
        sim->StateAt(sim->FrameTime(f)).world_from_head.inverse() * view.camera.cam_from_world.inverse();
    for (int i = 0; i < 68; ++i) {
      const int x = static_cast<int>(std::lround(lm[i].x)), y = static_cast<int>(std::lround(lm[i].y));
      if (x < 0 || y < 0 || x >= view.render.depth.cols || y >= view.render.depth.rows) continue;
      const float z = view.render.depth.at<float>(y, x);
      const int id = view.render.triangle.at<int>(y, x);
      if (z <= 0 || id < 0 || (id >> 24) != 0) continue;  // not on the head
      const Eigen::Vector3d cam((lm[i].x - view.camera.cx) / view.camera.fx * z,
                                (lm[i].y - view.camera.cy) / view.camera.fy * z, z);
      sum[i] += head_from_cam * cam;
      ++count[i];
    }
  }
  points->clear();
  int seen = 0;
  for (int i = 0; i < 68; ++i) {
    seen += count[i] > 0;
    points->push_back(count[i] > 0 ? Eigen::Vector3d(sum[i] / count[i])
                                   : Eigen::Vector3d(model.neutral().col(model.landmarks_ibug68()[i]).cast<double>()));
  }
  if (seen < 60) return Status::DataError("the detector found too few landmarks on the calibration renders");
  return Status::Ok();
}

Status WriteLandmarkEmbedding(const std::string& path, const std::vector<Eigen::Vector3d>& points) {
  nlohmann::json rows = nlohmann::json::array();
  for (const auto& p : points) rows.push_back({std::round(p.x() * 1e6) / 1e6, std::round(p.y() * 1e6) / 1e6, std::round(p.z() * 1e6) / 1e6});
  return WriteJsonAtomic(path, {{"format", "ibug68 head-frame points, metres"}, {"points", rows}}, 1);
}

Status ReadLandmarkEmbedding(const std::string& path, std::vector<Eigen::Vector3d>* points) {
  nlohmann::json j;
  HF_RETURN_IF_ERROR(ReadJson(path, &j));
  try {
    points->clear();
    for (const auto& p : j.at("points")) points->emplace_back(p.at(0).get<double>(), p.at(1).get<double>(), p.at(2).get<double>());
  } catch (const nlohmann::json::exception& e) {
    return Status::DataError(path + " is not a landmark embedding: " + e.what());
  }
  if (points->size() != 68) return Status::DataError(path + " does not hold 68 points");
  return Status::Ok();
}

std::vector<Eigen::Vector3d> DetectorLandmarkPoints(const FaceModel& model, const std::string& embedding_path) {
  std::vector<Eigen::Vector3d> points;
  if (!embedding_path.empty() && fs::exists(embedding_path)) {
    const Status s = ReadLandmarkEmbedding(embedding_path, &points);
    if (s.ok()) return points;
    HF_LOG(Warning) << s.message() << "; using the model's landmark vertices";
  }
  points.clear();
  for (int v : model.landmarks_ibug68()) points.push_back(model.neutral().col(v).cast<double>());
  return points;
}

}  // namespace headforge
