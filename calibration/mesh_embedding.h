// Where MediaPipe's face mesh (vision/face_mesh.h: 468 points) sits on the
// face model, measured as the 68 points' embedding is
// (calibration/landmark_embedding.h): the mean face rendered under light as
// it turns and nods, the mesh found on each render the way ingest finds it
// (the square placed from the 68 points, then from the mesh), and each point
// carried back to the head frame through the render's depth and its known
// pose. Points are the median of their renders, coordinate by coordinate:
// the network places a point the head hides (a far cheek) on what hides it,
// and the median leaves those renders out.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "capture/face_detector.h"
#include "core/face_model.h"
#include "core/hash.h"
#include "core/status.h"

namespace headforge {

inline constexpr int kMeshEmbeddingPoints = 468;

struct MeshEmbeddingReport {
  int renders = 0;        // renders the mesh was found on
  int points_seen = 0;    // points found on the head on at least `min_seen` renders
  // Median distance of a point's renders from its median (metres), over the
  // points: how far apart the renders place it.
  double median_spread = 0;
};

// 468 head-frame points (metres); a point seen on fewer than `min_seen`
// renders keeps the model's surface point nearest the mean of its neighbours
// (none is left undefined).
Status MeasureMeshEmbedding(const FaceModel& model, const FaceDetectorOptions& detector,
                            const std::string& landmark_model, const std::string& vision_models, int threads,
                            std::vector<Eigen::Vector3d>* points, MeshEmbeddingReport* report);

Status WriteMeshEmbedding(const std::string& path, const std::vector<Eigen::Vector3d>& points);
Status ReadMeshEmbedding(const std::string& path, std::vector<Eigen::Vector3d>* points);

// Adds the embedding file's contents to a stage's fingerprint ("" or a
// missing file: that the mesh is not used).
Status AddMeshEmbeddingInputs(const std::string& file, Hasher* hasher);

// The embedding shipped in data/ (for the ICT model and human-models' facemesh).
std::string DefaultMeshEmbedding();

// The mesh's outline (MediaPipe's face oval, 36 points from the forehead
// round the jaw): like the 68 points' jaw contour it follows the silhouette,
// and slides over the face as the head turns.
const std::vector<int>& MeshOvalPoints();

}  // namespace headforge
