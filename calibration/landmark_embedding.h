// Where the landmark detector's 68 points sit on the face model. Detectors
// follow their training annotations, which differ from the model's landmark
// vertices by millimetres (brows lower, eye corners inward, ...), enough to
// bias head poses by degrees. The embedding is measured once on simulator
// renders of the mean face under light, over a sweep of head rotations: each
// detected point is carried back to the head frame through the render's depth
// and the known pose, and the points are averaged.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "capture/face_detector.h"
#include "core/face_model.h"
#include "core/status.h"

namespace headforge {

// 68 head-frame points (metres); landmarks never seen keep the model's vertex.
Status MeasureLandmarkEmbedding(const FaceModel& model, const FaceDetectorOptions& detector,
                                const std::string& landmark_model, int threads, std::vector<Eigen::Vector3d>* points);

Status WriteLandmarkEmbedding(const std::string& path, const std::vector<Eigen::Vector3d>& points);
Status ReadLandmarkEmbedding(const std::string& path, std::vector<Eigen::Vector3d>* points);

// The 68 points a solver should use: the embedding file when it exists and
// loads, else the model's landmark vertices.
std::vector<Eigen::Vector3d> DetectorLandmarkPoints(const FaceModel& model, const std::string& embedding_path);

// The embedding shipped in data/ (for the ICT model and dlib's 68-point predictor).
std::string DefaultLandmarkEmbedding();

}  // namespace headforge
