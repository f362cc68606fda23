// cameras.json: the intrinsics of each camera and the pose of every view
// (camera x frame), as calibrate writes them and align re-expresses them in
// the head frame.
#pragma once

#include <Eigen/Geometry>
#include <nlohmann/json_fwd.hpp>
#include <string>
#include <vector>

#include "core/fs.h"
#include "core/status.h"

namespace headforge {

struct CameraIntrinsics {
  std::string name;
  // COLMAP's model names: PINHOLE (fx fy cx cy), SIMPLE_RADIAL (f cx cy k1),
  // RADIAL (f cx cy k1 k2), OPENCV (fx fy cx cy k1 k2 p1 p2).
  std::string model = "PINHOLE";
  int width = 0, height = 0;
  double fx = 0, fy = 0, cx = 0, cy = 0;
  double k1 = 0, k2 = 0, p1 = 0, p2 = 0;

  Eigen::Matrix3d K() const;
  // From a JSON object {name, model, width, height, fx, fy, cx, cy, k1, k2, p1, p2};
  // fy defaults to fx, the model to PINHOLE, distortion to 0. Throws
  // nlohmann::json::exception when a required field is missing.
  static CameraIntrinsics FromJson(const nlohmann::json& json);
  // Pixel of a camera-frame point, with distortion.
  Eigen::Vector2d Project(const Eigen::Vector3d& camera_point) const;
  // The pixel a distortion-free camera with the same fx, fy, cx, cy would see
  // (the inverse of the distortion, by fixed-point iteration).
  Eigen::Vector2d Undistort(const Eigen::Vector2d& pixel) const;
};

struct CameraView {
  std::string camera;
  int frame = 0;
  bool registered = false;
  Eigen::Isometry3d cam_from_world = Eigen::Isometry3d::Identity();
  Eigen::Vector3d Centre() const { return cam_from_world.inverse().translation(); }
};

// How far round the head one camera's views must spread to make a
// walk-around: the train stage's model choice, the frames it holds out and
// track's still head follow it.
constexpr double kWalkAroundSpreadDeg = 120.0;

struct CameraSet {
  static constexpr int kVersion = 1;  // of cameras.json; Read refuses another
  std::string mode;             // colmap, head-pose, rig
  std::string frame = "world";  // "world" (calibrate) or "head" (after align, or head-pose)
  std::vector<CameraIntrinsics> cameras;
  std::vector<CameraView> views;
  std::string notes;  // how they were obtained, in a line
  // The world's unit in metres where calibrate knows it (a rig file that says
  // so); 0: unknown (COLMAP's world has no unit).
  double metres_per_unit = 0.0;
  // Head-pose cameras whose poses features on the head's rigid part refined
  // (calibration/feature_poses.h): their motion from frame to frame is closer
  // than the landmarks', and track holds the head by them.
  bool poses_from_features = false;

  const CameraIntrinsics* FindCamera(const std::string& name) const;
  const CameraView* FindView(const std::string& camera, int frame) const;
  int registered() const;
  // How far round the head (the frame's origin, +y up) the registered views'
  // centres spread in azimuth, degrees: 360 minus the widest gap between
  // neighbouring azimuths (0 for fewer than two views). About 0 for a fixed
  // camera, 360 for a capture all round the head.
  double AzimuthSpreadDeg() const;
  // One camera whose views spread kWalkAroundSpreadDeg or more round the head:
  // a camera carried round a head (a walk-around video), not a fixed one.
  bool WalksRoundTheHead() const;

  Status Write(const fs::path& path) const;
  // Reads a file Write wrote, checking its version.
  static Status Read(const fs::path& path, CameraSet* set);
};

}  // namespace headforge
