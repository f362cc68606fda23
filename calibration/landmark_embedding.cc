#include "calibration/landmark_embedding.h"

#include <algorithm>
#include <cmath>
#include <functional>

#include "capture/landmarks.h"
#include "capture/simulator.h"
#include "core/json_io.h"
#include "core/log.h"

namespace headforge {

std::string DefaultLandmarkEmbedding() { return HEADFORGE_LANDMARK_EMBEDDING; }
std::string ViewLandmarkEmbedding() { return HEADFORGE_VIEW_LANDMARK_EMBEDDING; }
std::string IdentityLandmarkEmbedding() { return HEADFORGE_IDENTITY_LANDMARK_EMBEDDING; }

Status AddLandmarkEmbeddingInputs(const std::vector<std::string>& files, Hasher* hasher) {
  for (const std::string& file : files) {
    if (file.empty()) {
      hasher->Add(std::string("the face model's landmark vertices"));
      continue;
    }
    hasher->Add(std::string("landmark embedding"));
    HF_RETURN_IF_ERROR(hasher->AddFileDigest(file).WithContext("landmark embedding"));
  }
  return Status::Ok();
}

namespace {

// The 68 points of the detector and dlib's predictor on a render (none
// where no face is found).
RenderPointDetector Detector68(FaceDetector* faces, const LandmarkPredictor* predictor) {
  return [faces, predictor](const cv::Mat& image) {
    const auto found = faces->Detect(image);
    if (found.empty()) return std::vector<cv::Point2f>();
    const Landmarks68 lm = predictor->Predict(image, found[0].landmark_box);
    return std::vector<cv::Point2f>(lm.begin(), lm.end());
  };
}

// Renders the mean face by `scene_text`, detects the 68 points in every frame
// and hands each one that lands on the head to `use`.
Status ForEachDetectedPoint(const std::string& scene_text, const FaceModel& model, const FaceDetectorOptions& detector,
                            const std::string& landmark_model, int threads, const RenderedPointUse& use,
                            const RenderedDirectionFilter& want = nullptr) {
  std::unique_ptr<FaceDetector> faces;
  HF_RETURN_IF_ERROR(FaceDetector::Create(detector, &faces));
  std::unique_ptr<LandmarkPredictor> predictor;
  HF_RETURN_IF_ERROR(LandmarkPredictor::Load(landmark_model, &predictor));
  return ForEachRenderedPoint(scene_text, model, threads, Detector68(faces.get(), predictor.get()), use, want);
}

}  // namespace

Status ForEachRenderedPoint(const std::string& scene_text, const FaceModel& model, int threads,
                            const RenderPointDetector& detect, const RenderedPointUse& use,
                            const RenderedDirectionFilter& want) {
  Scene scene;
  HF_RETURN_IF_ERROR(ParseScene(scene_text, "landmark embedding scene", &scene));
  std::unique_ptr<Simulator> sim;
  HF_RETURN_IF_ERROR(Simulator::Create(scene, model, threads, &sim));
  for (int f = 0; f < sim->num_frames(); ++f) {
    // The camera RenderView places, and the head's pose at the frame's time.
    const double t = sim->FrameTime(f);
    const Eigen::Isometry3d head_from_cam =
        sim->StateAt(t).world_from_head.inverse() * sim->CameraAt(0, t).cam_from_world.inverse();
    if (want && !want(head_from_cam.translation())) continue;
    const SimulatedView view = sim->RenderView(f, 0);
    const std::vector<cv::Point2f> points = detect(view.image);
    for (size_t i = 0; i < points.size(); ++i) {
      const int x = static_cast<int>(std::lround(points[i].x)), y = static_cast<int>(std::lround(points[i].y));
      if (x < 0 || y < 0 || x >= view.render.depth.cols || y >= view.render.depth.rows) continue;
      const float z = view.render.depth.at<float>(y, x);
      const int id = view.render.triangle.at<int>(y, x);
      if (z <= 0 || id < 0 || (id >> 24) != 0) continue;  // not on the head
      const Eigen::Vector3d cam((points[i].x - view.camera.cx) / view.camera.fx * z,
                                (points[i].y - view.camera.cy) / view.camera.fy * z, z);
      use(int(i), head_from_cam * cam, head_from_cam.translation());
    }
  }
  return Status::Ok();
}

std::string EmbeddingScene(int frames, double yaw, double yaw_period, double pitch, double pitch_period,
                           const SubjectLook& look) {
  std::string identity = "[0.0]";
  if (look.alpha.size() > 0) {
    identity = "[";
    for (int i = 0; i < look.alpha.size(); ++i) identity += (i ? ", " : "") + std::to_string(look.alpha[i]);
    identity += "]";
  }
  char text[2048];
  std::snprintf(text, sizeof(text),
                "name = \"landmark_embedding\"\nfps = 25\nframes = %d\neffects = [\"lighting\"]\n"
                "[subject]\nidentity = %s\n[appearance]\nskin = [%.3f, %.3f, %.3f]\n[background]\ntype = \"flat\"\n"
                "[camera]\nposition = [0.0, 0.0, 0.65]\n[camera.intrinsics]\nwidth = 512\nheight = 512\nfocal = 1100.0\n"
                "[head]\nyaw = { type = \"sine\", amplitude = %.1f, period = %.2f }\n"
                "pitch = { type = \"sine\", amplitude = %.1f, period = %.2f }\n"
                "[effect.lighting]\nx = %.3f\ny = %.3f\nz = %.3f\nambient = %.3f\ndiffuse = %.3f\n",
                frames, identity.c_str(), look.skin.x(), look.skin.y(), look.skin.z(), yaw, yaw_period, pitch,
                pitch_period, look.light.x(), look.light.y(), look.light.z(), look.ambient, look.diffuse);
  return text;
}

Status MeasureLandmarkEmbedding(const FaceModel& model, const FaceDetectorOptions& detector,
                                const std::string& landmark_model, int threads, std::vector<Eigen::Vector3d>* points) {
  // The mean face under the default look; landmarks never found keep the model's vertex.
  std::vector<int> count;
  HF_RETURN_IF_ERROR(MeasureSubjectLandmarks(model, detector, landmark_model, threads, SubjectLook(), points, &count));
  int seen = 0;
  for (int i = 0; i < 68; ++i) {
    if (count[i] > 0)
      ++seen;
    else
      (*points)[i] = model.neutral().col(model.landmarks_ibug68()[i]).cast<double>();
  }
  if (seen < 60) return Status::DataError("the detector found too few landmarks on the calibration renders");
  return Status::Ok();
}

Status MeasureSubjectLandmarks(const FaceModel& model, const FaceDetectorOptions& detector,
                               const std::string& landmark_model, int threads, const SubjectLook& look,
                               std::vector<Eigen::Vector3d>* points, std::vector<int>* seen) {
  std::vector<Eigen::Vector3d> sum(68, Eigen::Vector3d::Zero());
  std::vector<int> count(68, 0);
  HF_RETURN_IF_ERROR(ForEachDetectedPoint(EmbeddingScene(60, 25.0, 2.4, 12.0, 1.1, look), model, detector,
                                          landmark_model, threads,
                                          [&](int i, const Eigen::Vector3d& p, const Eigen::Vector3d&) {
                                            sum[i] += p;
                                            ++count[i];
                                          }));
  points->assign(68, Eigen::Vector3d::Zero());
  for (int i = 0; i < 68; ++i)
    if (count[i] > 0) (*points)[i] = sum[i] / count[i];
  *seen = std::move(count);
  return Status::Ok();
}

Status MeasureViewLandmarkEmbedding(const FaceModel& model, const FaceDetectorOptions& detector,
                                    const std::string& landmark_model, int threads, LandmarkEmbedding* embedding,
                                    const std::vector<int>& only_nodes) {
  LandmarkEmbedding out;
  HF_RETURN_IF_ERROR(MeasureLandmarkEmbedding(model, detector, landmark_model, threads, &out.points));
  for (int y = -60; y <= 60; y += 10) out.yaw_deg.push_back(y);
  for (int p = -20; p <= 20; p += 10) out.pitch_deg.push_back(p);
  const size_t num_nodes = out.yaw_deg.size() * out.pitch_deg.size();
  std::vector<Eigen::Vector3d> sum(num_nodes * 68, Eigen::Vector3d::Zero());
  std::vector<double> weight(num_nodes * 68, 0.0);
  std::vector<bool> measured(num_nodes, only_nodes.empty());
  for (int n : only_nodes) {
    if (n < 0 || size_t(n) >= num_nodes) return Status::InvalidArgument("no view grid node " + std::to_string(n));
    measured[size_t(n)] = true;
  }
  RenderedDirectionFilter want;
  if (!only_nodes.empty())
    want = [&](const Eigen::Vector3d& toward) {
      for (const auto& [node, w] : out.NodeWeights(toward))
        if (measured[size_t(node)] && w > 0) return true;
      return false;
    };
  // Turning +-65 degrees and nodding +-22, each detection shared among the
  // four nodes around its direction by the bilinear weights.
  HF_RETURN_IF_ERROR(ForEachDetectedPoint(EmbeddingScene(400, 65.0, 3.3, 22.0, 0.7), model, detector, landmark_model,
                                          threads, [&](int i, const Eigen::Vector3d& p, const Eigen::Vector3d& toward) {
                                            for (const auto& [node, w] : out.NodeWeights(toward)) {
                                              if (!measured[size_t(node)]) continue;
                                              sum[node * 68 + i] += w * p;
                                              weight[node * 68 + i] += w;
                                            }
                                          }, want));
  // A node that saw a landmark little leans toward the points over every
  // direction: three detections' weight make it the node's own.
  constexpr double kFullWeight = 3.0;
  for (size_t n = 0; n < num_nodes; ++n) {
    std::vector<Eigen::Vector3d> points(68);
    for (int i = 0; i < 68; ++i) {
      const double w = weight[n * 68 + i];
      const Eigen::Vector3d own = w > 0 ? Eigen::Vector3d(sum[n * 68 + i] / w) : out.points[i];
      const double t = std::min(w / kFullWeight, 1.0);
      points[i] = t * own + (1 - t) * out.points[i];
    }
    out.nodes.push_back(std::move(points));
  }
  *embedding = std::move(out);
  return Status::Ok();
}

namespace {
nlohmann::json PointRows(const std::vector<Eigen::Vector3d>& points) {
  nlohmann::json rows = nlohmann::json::array();
  for (const auto& p : points) rows.push_back({std::round(p.x() * 1e6) / 1e6, std::round(p.y() * 1e6) / 1e6, std::round(p.z() * 1e6) / 1e6});
  return rows;
}
}  // namespace

Status WriteLandmarkEmbedding(const std::string& path, const std::vector<Eigen::Vector3d>& points) {
  return WriteJsonAtomic(path, {{"format", "ibug68 head-frame points, metres"}, {"points", PointRows(points)}}, 1);
}

Status WriteLandmarkEmbedding(const std::string& path, const LandmarkEmbedding& embedding) {
  nlohmann::json j = {{"format", "ibug68 head-frame points, metres; nodes: the points seen from each camera direction"},
                      {"points", PointRows(embedding.points)}};
  if (embedding.view_dependent()) {
    j["yaw_deg"] = embedding.yaw_deg;
    j["pitch_deg"] = embedding.pitch_deg;
    nlohmann::json nodes = nlohmann::json::array();
    for (const auto& points : embedding.nodes) nodes.push_back({{"points", PointRows(points)}});
    j["nodes"] = nodes;
  }
  if (!embedding.identity.empty()) {
    // Per landmark three rows (x, y, z) of K coefficients.
    nlohmann::json blocks = nlohmann::json::array();
    for (const auto& block : embedding.identity) {
      nlohmann::json rows = nlohmann::json::array();
      for (int r = 0; r < 3; ++r) {
        std::vector<double> row(block.cols());
        for (int c = 0; c < block.cols(); ++c) row[c] = std::round(block(r, c) * 1e8) / 1e8;
        rows.push_back(row);
      }
      blocks.push_back(rows);
    }
    j["identity"] = blocks;
    j["format"] = "ibug68 head-frame points at identity 0, metres; identity: per point [3][K], metres per standard "
                  "deviation of each identity coefficient";
  }
  return WriteJsonAtomic(path, j, 0);
}

namespace {
Status ReadPoints(const nlohmann::json& rows, const std::string& path, std::vector<Eigen::Vector3d>* points) {
  try {
    points->clear();
    for (const auto& p : rows) points->emplace_back(p.at(0).get<double>(), p.at(1).get<double>(), p.at(2).get<double>());
  } catch (const nlohmann::json::exception& e) {
    return Status::DataError(path + " is not a landmark embedding: " + e.what());
  }
  if (points->size() != 68) return Status::DataError(path + " does not hold 68 points");
  return Status::Ok();
}
}  // namespace

Status ReadLandmarkEmbedding(const std::string& path, std::vector<Eigen::Vector3d>* points) {
  LandmarkEmbedding e;
  HF_RETURN_IF_ERROR(ReadLandmarkEmbedding(path, &e));
  *points = std::move(e.points);
  return Status::Ok();
}

Status ReadLandmarkEmbedding(const std::string& path, LandmarkEmbedding* embedding) {
  nlohmann::json j;
  HF_RETURN_IF_ERROR(ReadJson(path, &j));
  if (!j.is_object() || !j.contains("points")) return Status::DataError(path + " is not a landmark embedding (no points)");
  LandmarkEmbedding out;
  HF_RETURN_IF_ERROR(ReadPoints(j["points"], path, &out.points));
  if (j.contains("nodes")) {
    try {
      out.yaw_deg = j.at("yaw_deg").get<std::vector<double>>();
      out.pitch_deg = j.at("pitch_deg").get<std::vector<double>>();
      for (const auto& node : j.at("nodes")) {
        std::vector<Eigen::Vector3d> points;
        HF_RETURN_IF_ERROR(ReadPoints(node.at("points"), path + " (a grid node)", &points));
        out.nodes.push_back(std::move(points));
      }
    } catch (const nlohmann::json::exception& e) {
      return Status::DataError(path + " has a malformed view grid: " + e.what());
    }
    auto ascending = [](const std::vector<double>& v) {
      for (size_t i = 1; i < v.size(); ++i)
        if (!(v[i] > v[i - 1])) return false;
      return !v.empty();
    };
    if (!ascending(out.yaw_deg) || !ascending(out.pitch_deg) ||
        out.nodes.size() != out.yaw_deg.size() * out.pitch_deg.size())
      return Status::DataError(path + ": the view grid's angles must ascend and its nodes number yaws x pitches");
  }
  if (j.contains("identity")) {
    try {
      for (const auto& rows : j.at("identity")) {
        const auto x = rows.at(0).get<std::vector<double>>(), y = rows.at(1).get<std::vector<double>>(),
                   z = rows.at(2).get<std::vector<double>>();
        if (x.empty() || y.size() != x.size() || z.size() != x.size() ||
            (!out.identity.empty() && int(x.size()) != out.identity[0].cols()))
          return Status::DataError(path + ": every identity block must have three rows of one length");
        Eigen::Matrix<double, 3, Eigen::Dynamic> block(3, int(x.size()));
        for (size_t c = 0; c < x.size(); ++c) block.col(int(c)) = Eigen::Vector3d(x[c], y[c], z[c]);
        out.identity.push_back(std::move(block));
      }
    } catch (const nlohmann::json::exception& e) {
      return Status::DataError(path + " has malformed identity columns: " + e.what());
    }
    if (out.identity.size() != 68) return Status::DataError(path + " does not hold identity columns for 68 points");
  }
  *embedding = std::move(out);
  return Status::Ok();
}

std::vector<std::pair<int, double>> LandmarkEmbedding::NodeWeights(const Eigen::Vector3d& toward_camera) const {
  if (yaw_deg.empty() || pitch_deg.empty()) return {};
  const Eigen::Vector3d d = toward_camera.normalized();
  const double yaw = std::atan2(d.x(), d.z()) * 180.0 / M_PI;
  const double pitch = std::asin(std::clamp(d.y(), -1.0, 1.0)) * 180.0 / M_PI;
  // Position between grid lines: index and fraction, clamped at the ends.
  auto locate = [](const std::vector<double>& grid, double x, int* i, double* t) {
    const int n = int(grid.size());
    if (n == 1 || x <= grid.front()) {
      *i = 0;
      *t = 0;
      return;
    }
    if (x >= grid.back()) {
      *i = n - 2;
      *t = 1;
      return;
    }
    *i = int(std::upper_bound(grid.begin(), grid.end(), x) - grid.begin()) - 1;
    *t = (x - grid[*i]) / (grid[*i + 1] - grid[*i]);
  };
  int iy, ip;
  double ty, tp;
  locate(yaw_deg, yaw, &iy, &ty);
  locate(pitch_deg, pitch, &ip, &tp);
  const int ny = int(yaw_deg.size()), np = int(pitch_deg.size());
  std::vector<std::pair<int, double>> out;
  for (int b = 0; b < (np > 1 ? 2 : 1); ++b) {
    for (int a = 0; a < (ny > 1 ? 2 : 1); ++a) {
      const double w = (ny > 1 ? (a ? ty : 1 - ty) : 1.0) * (np > 1 ? (b ? tp : 1 - tp) : 1.0);
      if (w > 0) out.emplace_back((ip + b) * ny + iy + a, w);
    }
  }
  return out;
}

LandmarkEmbedding LoadLandmarkEmbedding(const FaceModel& model, const std::string& embedding_path) {
  LandmarkEmbedding e;
  if (!embedding_path.empty() && fs::exists(embedding_path)) {
    const Status s = ReadLandmarkEmbedding(embedding_path, &e);
    if (s.ok()) return e;
    HF_LOG(Warning) << s.message() << "; using the model's landmark vertices";
  }
  e = LandmarkEmbedding();
  for (int v : model.landmarks_ibug68()) e.points.push_back(model.neutral().col(v).cast<double>());
  return e;
}

std::vector<Eigen::Vector3d> DetectorLandmarkPoints(const FaceModel& model, const std::string& embedding_path) {
  return LoadLandmarkEmbedding(model, embedding_path).points;
}

}  // namespace headforge
