#include "core/camera_set.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/json_io.h"

namespace headforge {

Eigen::Matrix3d CameraIntrinsics::K() const {
  Eigen::Matrix3d k;
  k << fx, 0, cx, 0, fy, cy, 0, 0, 1;
  return k;
}

CameraIntrinsics CameraIntrinsics::FromJson(const nlohmann::json& c) {
  CameraIntrinsics in;
  in.name = c.at("name").get<std::string>();
  in.model = c.value("model", "PINHOLE");
  in.width = c.at("width").get<int>();
  in.height = c.at("height").get<int>();
  in.fx = c.at("fx").get<double>();
  in.fy = c.value("fy", in.fx);
  in.cx = c.at("cx").get<double>();
  in.cy = c.at("cy").get<double>();
  in.k1 = c.value("k1", 0.0);
  in.k2 = c.value("k2", 0.0);
  in.p1 = c.value("p1", 0.0);
  in.p2 = c.value("p2", 0.0);
  return in;
}

Eigen::Vector2d CameraIntrinsics::Project(const Eigen::Vector3d& p) const {
  const double x = p.x() / p.z(), y = p.y() / p.z();
  const double r2 = x * x + y * y;
  const double radial = 1 + k1 * r2 + k2 * r2 * r2;
  const double xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x);
  const double yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y;
  return Eigen::Vector2d(fx * xd + cx, fy * yd + cy);
}

Eigen::Vector2d CameraIntrinsics::Undistort(const Eigen::Vector2d& pixel) const {
  if (k1 == 0 && k2 == 0 && p1 == 0 && p2 == 0) return pixel;
  const Eigen::Vector2d xd((pixel.x() - cx) / fx, (pixel.y() - cy) / fy);
  Eigen::Vector2d x = xd;
  for (int i = 0; i < 20; ++i) {
    const double r2 = x.squaredNorm();
    const double radial = 1 + k1 * r2 + k2 * r2 * r2;
    const Eigen::Vector2d tangential(2 * p1 * x.x() * x.y() + p2 * (r2 + 2 * x.x() * x.x()),
                                     p1 * (r2 + 2 * x.y() * x.y()) + 2 * p2 * x.x() * x.y());
    x = (xd - tangential) / radial;
  }
  return Eigen::Vector2d(fx * x.x() + cx, fy * x.y() + cy);
}

const CameraIntrinsics* CameraSet::FindCamera(const std::string& name) const {
  for (const auto& c : cameras)
    if (c.name == name) return &c;
  return nullptr;
}

const CameraView* CameraSet::FindView(const std::string& camera, int frame) const {
  for (const auto& v : views)
    if (v.camera == camera && v.frame == frame) return &v;
  return nullptr;
}

double CameraSet::AzimuthSpreadDeg() const {
  std::vector<double> azimuths;
  for (const CameraView& v : views)
    if (v.registered) {
      const Eigen::Vector3d c = v.Centre();
      if (std::hypot(c.x(), c.z()) > 1e-9) azimuths.push_back(std::atan2(c.x(), c.z()) * 180 / M_PI);
    }
  if (azimuths.size() < 2) return 0;
  std::sort(azimuths.begin(), azimuths.end());
  double widest_gap = 360 - (azimuths.back() - azimuths.front());
  for (size_t i = 1; i < azimuths.size(); ++i) widest_gap = std::max(widest_gap, azimuths[i] - azimuths[i - 1]);
  return 360 - widest_gap;
}

bool CameraSet::WalksRoundTheHead() const {
  return cameras.size() == 1 && AzimuthSpreadDeg() >= kWalkAroundSpreadDeg;
}

int CameraSet::registered() const {
  int n = 0;
  for (const auto& v : views) n += v.registered;
  return n;
}


Status CameraSet::Write(const fs::path& path) const {
  nlohmann::json cams = nlohmann::json::array(), views_json = nlohmann::json::array();
  for (const auto& c : cameras)
    cams.push_back({{"name", c.name}, {"model", c.model}, {"width", c.width}, {"height", c.height},
                    {"fx", c.fx}, {"fy", c.fy}, {"cx", c.cx}, {"cy", c.cy},
                    {"k1", c.k1}, {"k2", c.k2}, {"p1", c.p1}, {"p2", c.p2}});
  for (const auto& v : views) {
    nlohmann::json j = {{"camera", v.camera}, {"frame", v.frame}, {"registered", v.registered}};
    if (v.registered) j["cam_from_world"] = PoseToJson(v.cam_from_world);
    views_json.push_back(j);
  }
  nlohmann::json root = {{"version", kVersion},  {"mode", mode},       {"frame", frame},
                         {"notes", notes}, {"cameras", cams},    {"views", views_json},
                         {"registered", registered()}, {"total", views.size()}};
  if (metres_per_unit > 0) root["metres_per_unit"] = metres_per_unit;
  if (poses_from_features) root["poses_from_features"] = true;
  return WriteJsonAtomic(path, root, 1);
}

Status CameraSet::Read(const fs::path& path, CameraSet* set) {
  nlohmann::json root;
  // cameras.json comes from calibrate; align re-expresses it as cameras_head.json.
  const std::string stage = path.filename() == "cameras_head.json" ? "align" : "calibrate";
  HF_RETURN_IF_ERROR(ReadArtefact(path, kVersion, stage, &root));
  CameraSet s;
  try {
    s.mode = root.value("mode", "");
    s.frame = root.value("frame", "world");
    s.notes = root.value("notes", "");
    s.metres_per_unit = root.value("metres_per_unit", 0.0);
    s.poses_from_features = root.value("poses_from_features", false);
    for (const auto& c : root.at("cameras")) {
      const CameraIntrinsics in = CameraIntrinsics::FromJson(c);
      s.cameras.push_back(in);
    }
    for (const auto& v : root.at("views")) {
      CameraView view;
      view.camera = v.at("camera").get<std::string>();
      view.frame = v.at("frame").get<int>();
      view.registered = v.value("registered", false);
      if (view.registered) view.cam_from_world = PoseFromJson(v.at("cam_from_world"));
      s.views.push_back(view);
    }
  } catch (const nlohmann::json::exception& e) {
    return Status::DataError(path.string() + " is not a valid cameras file: " + e.what());
  }
  *set = std::move(s);
  return Status::Ok();
}

}  // namespace headforge
