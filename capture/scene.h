// A simulated capture, described by a TOML scene file (docs/simulator.md,
// examples in scenes/). A scene names its effects; nothing else is simulated.
#pragma once

#include <Eigen/Core>
#include <map>
#include <string>
#include <vector>

#include "capture/curves.h"
#include "core/status.h"

namespace headforge {

// The effects a scene may enable, in the order they are applied.
const std::vector<std::string>& KnownEffects();

struct SceneIntrinsics {
  int width = 512, height = 512;
  double focal = 0.0;       // pixels; 0: from fov_deg
  double fov_deg = 40.0;    // horizontal field of view when focal is 0
  double cx = -1, cy = -1;  // principal point; negative: the image centre
  double k1 = 0.0, k2 = 0.0;  // radial distortion, used by the lens_distortion effect
  double fx() const;
  double cx_or_centre() const { return cx >= 0 ? cx : (width - 1) / 2.0; }
  double cy_or_centre() const { return cy >= 0 ? cy : (height - 1) / 2.0; }
};

struct SceneCamera {
  // "static": one fixed camera; "orbit": one camera circling the target;
  // "rig": `count` fixed cameras on an arc, or at `positions`; "handheld": one
  // camera near `position` with smooth random shake.
  std::string rig = "static";
  Eigen::Vector3d position = Eigen::Vector3d(0, 0, 0.6);
  Eigen::Vector3d target = Eigen::Vector3d(0, 0, 0);
  double radius = 0.8;                    // orbit and rig
  std::vector<double> elevations = {0.0};  // orbit rings, degrees
  int count = 8;                          // rig
  double arc_deg = 180.0;                 // rig: cameras spread over this azimuth arc
  double elevation_deg = 0.0;             // rig
  std::vector<Eigen::Vector3d> positions;  // rig: explicit positions (override count/arc)
  double shake_m = 0.01, shake_deg = 1.0, shake_timescale = 0.7;  // handheld
  SceneIntrinsics intrinsics;
};

struct Scene {
  std::string name = "scene";
  double duration = 2.0;  // seconds
  double fps = 25.0;
  int frames = 0;  // 0: duration x fps
  int seed = 0;
  int supersample = 3;

  // Subject.
  std::vector<double> identity;  // explicit coefficients (alpha)
  bool random_identity = true;
  int identity_seed = 1, identity_modes = 20;
  double identity_scale = 1.0;

  // Appearance (colours RGB in [0, 1]).
  Eigen::Vector3f skin = Eigen::Vector3f(0.78f, 0.58f, 0.47f);
  Eigen::Vector3f hair = Eigen::Vector3f(0.16f, 0.11f, 0.08f);
  Eigen::Vector3f iris = Eigen::Vector3f(0.30f, 0.22f, 0.12f);
  Eigen::Vector3f teeth = Eigen::Vector3f(0.92f, 0.90f, 0.84f);
  double freckles = 0.3, pores = 0.5;
  int appearance_seed = 2;
  int texture_size = 1024;

  // Background: "flat", "backdrop" (a textured plane behind the head) or
  // "room" (a textured box around the scene).
  std::string background = "flat";
  Eigen::Vector3f background_colour = Eigen::Vector3f(0.35f, 0.45f, 0.6f);
  double backdrop_distance = 0.8, room_size = 4.0;
  int background_seed = 5;

  SceneCamera camera;
  // Head pose curves: rotation in degrees about the head's y (yaw), x (pitch),
  // z (roll); translation in metres.
  Curve yaw, pitch, roll, tx, ty, tz;
  std::map<std::string, Curve> expressions;  // blendshape name -> weight curve

  std::vector<std::string> effects;
  // Parameters by effect name; an entry for an effect not listed does nothing.
  std::map<std::string, std::map<std::string, double>> effect_params;

  int FrameCount() const;
  bool HasEffect(const std::string& name) const;
  // The effect's parameter, or `fallback`.
  double Param(const std::string& effect, const std::string& key, double fallback) const;
  Status Check() const;
};

// Parses a scene file; errors name the file and the offending key.
Status LoadScene(const std::string& path, Scene* scene);
Status ParseScene(const std::string& toml_text, const std::string& source_name, Scene* scene);

}  // namespace headforge
