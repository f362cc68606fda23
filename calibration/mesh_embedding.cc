#include "calibration/mesh_embedding.h"

#include <algorithm>
#include <cmath>

#include "calibration/landmark_embedding.h"
#include "capture/landmarks.h"
#include "core/json_io.h"
#include "core/log.h"
#include "vision/face_mesh.h"

namespace headforge {

std::string DefaultMeshEmbedding() { return HEADFORGE_MESH_EMBEDDING; }

Status AddMeshEmbeddingInputs(const std::string& file, Hasher* hasher) {
  if (file.empty() || !fs::exists(file)) {
    hasher->Add(std::string("no face mesh embedding"));
    return Status::Ok();
  }
  hasher->Add(std::string("face mesh embedding"));
  return hasher->AddFileDigest(file).WithContext("face mesh embedding");
}

const std::vector<int>& MeshOvalPoints() {
  static const std::vector<int> oval = {10,  338, 297, 332, 284, 251, 389, 356, 454, 323, 361, 288,
                                        397, 365, 379, 378, 400, 377, 152, 148, 176, 149, 150, 136,
                                        172, 58,  132, 93,  234, 127, 162, 21,  54,  103, 67,  109};
  return oval;
}

Status MeasureMeshEmbedding(const FaceModel& model, const FaceDetectorOptions& detector,
                            const std::string& landmark_model, const std::string& vision_models, int threads,
                            std::vector<Eigen::Vector3d>* points, MeshEmbeddingReport* report) {
  std::unique_ptr<FaceDetector> faces;
  HF_RETURN_IF_ERROR(FaceDetector::Create(detector, &faces));
  std::unique_ptr<LandmarkPredictor> predictor;
  HF_RETURN_IF_ERROR(LandmarkPredictor::Load(landmark_model, &predictor));
  std::unique_ptr<FaceMesh> mesh;
  HF_RETURN_IF_ERROR(FaceMesh::Load(vision_models, &mesh));
  MeshEmbeddingReport out;
  const RenderPointDetector detect = [&](const cv::Mat& image) {
    const auto found = faces->Detect(image);
    if (found.empty()) return std::vector<cv::Point2f>();
    const Landmarks68 lm = predictor->Predict(image, found[0].landmark_box);
    const FaceMeshResult m = mesh->Refine(image, FaceRegionFrom68(std::vector<cv::Point2f>(lm.begin(), lm.end())));
    if (m.score < 0.5f) return std::vector<cv::Point2f>();
    ++out.renders;
    std::vector<cv::Point2f> flat;
    for (const cv::Point3f& p : m.points) flat.emplace_back(p.x, p.y);
    return flat;
  };
  std::vector<std::vector<Eigen::Vector3d>> seen(kMeshEmbeddingPoints);
  // The 68 points' sweep, twice as many renders: +-25 degrees of turn, +-12 of nod.
  HF_RETURN_IF_ERROR(ForEachRenderedPoint(EmbeddingScene(120, 25.0, 2.4, 12.0, 1.1), model, threads, detect,
                                          [&](int i, const Eigen::Vector3d& p, const Eigen::Vector3d&) {
                                            seen[size_t(i)].push_back(p);
                                          }));
  constexpr int kMinSeen = 10;
  points->assign(kMeshEmbeddingPoints, Eigen::Vector3d::Zero());
  std::vector<bool> measured(kMeshEmbeddingPoints, false);
  std::vector<double> spreads;
  for (int i = 0; i < kMeshEmbeddingPoints; ++i) {
    std::vector<Eigen::Vector3d>& s = seen[size_t(i)];
    if (int(s.size()) < kMinSeen) continue;
    Eigen::Vector3d median;
    for (int c = 0; c < 3; ++c) {
      std::vector<double> v;
      for (const auto& p : s) v.push_back(p[c]);
      std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
      median[c] = v[v.size() / 2];
    }
    (*points)[size_t(i)] = median;
    measured[size_t(i)] = true;
    std::vector<double> d;
    for (const auto& p : s) d.push_back((p - median).norm());
    std::nth_element(d.begin(), d.begin() + d.size() / 2, d.end());
    spreads.push_back(d[d.size() / 2]);
    ++out.points_seen;
  }
  if (out.points_seen < kMeshEmbeddingPoints / 2)
    return Status::DataError("the face mesh found too few of its points on the calibration renders (" +
                             std::to_string(out.points_seen) + " of " + std::to_string(kMeshEmbeddingPoints) + ")");
  // A point never seen (none is expected on this sweep) takes the surface
  // vertex nearest the measured points' mean position.
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (int i = 0; i < kMeshEmbeddingPoints; ++i)
    if (measured[size_t(i)]) mean += (*points)[size_t(i)] / out.points_seen;
  for (int i = 0; i < kMeshEmbeddingPoints; ++i)
    if (!measured[size_t(i)]) (*points)[size_t(i)] = mean;
  std::nth_element(spreads.begin(), spreads.begin() + spreads.size() / 2, spreads.end());
  out.median_spread = spreads[spreads.size() / 2];
  if (report) *report = out;
  return Status::Ok();
}

Status WriteMeshEmbedding(const std::string& path, const std::vector<Eigen::Vector3d>& points) {
  if (points.size() != size_t(kMeshEmbeddingPoints))
    return Status::InvalidArgument("a face mesh embedding holds 468 points");
  nlohmann::json rows = nlohmann::json::array();
  for (const auto& p : points)
    rows.push_back({std::round(p.x() * 1e6) / 1e6, std::round(p.y() * 1e6) / 1e6, std::round(p.z() * 1e6) / 1e6});
  return WriteJsonAtomic(path, {{"format", "facemesh468 head-frame points, metres"}, {"points", rows}}, 0);
}

Status ReadMeshEmbedding(const std::string& path, std::vector<Eigen::Vector3d>* points) {
  nlohmann::json j;
  HF_RETURN_IF_ERROR(ReadJson(path, &j));
  try {
    if (j.at("format").get<std::string>().rfind("facemesh468", 0) != 0)
      return Status::DataError(path + " is not a face mesh embedding (format " + j.at("format").dump() + ")");
    points->clear();
    for (const auto& p : j.at("points"))
      points->emplace_back(p.at(0).get<double>(), p.at(1).get<double>(), p.at(2).get<double>());
  } catch (const nlohmann::json::exception& e) {
    return Status::DataError(path + " is not a face mesh embedding: " + e.what());
  }
  if (points->size() != size_t(kMeshEmbeddingPoints)) return Status::DataError(path + " does not hold 468 points");
  return Status::Ok();
}

}  // namespace headforge
