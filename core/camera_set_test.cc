#include "core/camera_set.h"

#include <gtest/gtest.h>

#include "core/json_io.h"

namespace headforge {
namespace {

TEST(CameraSet, RoundTripsAndChecksItsVersion) {
  const fs::path dir = fs::temp_directory_path() / "hf_camera_set";
  fs::remove_all(dir);
  fs::create_directories(dir);
  CameraSet set;
  set.mode = "colmap";
  set.frame = "world";
  set.notes = "SIMPLE_RADIAL, 36 of 36 registered";
  CameraIntrinsics in;
  in.name = "cam0";
  in.model = "OPENCV";
  in.width = 640;
  in.height = 480;
  in.fx = 512.25;
  in.fy = 511.5;
  in.cx = 319.5;
  in.cy = 240.125;
  in.k1 = -0.01;
  in.k2 = 0.002;
  in.p1 = 1e-4;
  in.p2 = -2e-4;
  set.cameras = {in};
  CameraView a{"cam0", 0, true, Eigen::Isometry3d::Identity()};
  a.cam_from_world.translate(Eigen::Vector3d(0.1, -0.2, 0.8));
  a.cam_from_world.rotate(Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized()));
  CameraView b{"cam0", 1, false, Eigen::Isometry3d::Identity()};
  set.views = {a, b};
  ASSERT_TRUE(set.Write(dir / "cameras.json").ok());
  CameraSet read;
  ASSERT_TRUE(CameraSet::Read(dir / "cameras.json", &read).ok());
  EXPECT_EQ(read.mode, "colmap");
  EXPECT_EQ(read.frame, "world");
  EXPECT_EQ(read.notes, set.notes);
  ASSERT_EQ(read.cameras.size(), 1u);
  const CameraIntrinsics& r = read.cameras[0];
  EXPECT_EQ(r.model, "OPENCV");
  EXPECT_EQ(r.width, 640);
  EXPECT_EQ(r.height, 480);
  EXPECT_EQ(r.fx, in.fx);
  EXPECT_EQ(r.fy, in.fy);
  EXPECT_EQ(r.cx, in.cx);
  EXPECT_EQ(r.cy, in.cy);
  EXPECT_EQ(r.k1, in.k1);
  EXPECT_EQ(r.k2, in.k2);
  EXPECT_EQ(r.p1, in.p1);
  EXPECT_EQ(r.p2, in.p2);
  ASSERT_EQ(read.views.size(), 2u);
  EXPECT_TRUE(read.views[0].registered);
  EXPECT_TRUE(read.views[0].cam_from_world.matrix().isApprox(a.cam_from_world.matrix(), 0.0));
  EXPECT_FALSE(read.views[1].registered);
  EXPECT_EQ(read.registered(), 1);
  ASSERT_TRUE(read.Write(dir / "again.json").ok());
  std::string first, second;
  ASSERT_TRUE(ReadFileToString(dir / "cameras.json", &first).ok());
  ASSERT_TRUE(ReadFileToString(dir / "again.json", &second).ok());
  EXPECT_EQ(first, second);

  nlohmann::json json;
  ASSERT_TRUE(ReadJson(dir / "cameras.json", &json).ok());
  json["version"] = 0;
  ASSERT_TRUE(WriteJsonAtomic(dir / "cameras_head.json", json).ok());
  const Status old = CameraSet::Read(dir / "cameras_head.json", &read);
  EXPECT_EQ(old.code(), Status::Code::kDataError);
  EXPECT_NE(old.message().find("run headforge align again"), std::string::npos) << old.message();
}

// Views on a ring round the head at the given azimuths (degrees, 0 = in
// front, +90 = toward +x), looking at the origin.
CameraSet Ring(const std::vector<double>& azimuths) {
  CameraSet set;
  set.cameras.emplace_back();
  set.cameras.back().name = "cam";
  int frame = 0;
  for (double a : azimuths) {
    CameraView v;
    v.camera = "cam";
    v.frame = frame++;
    v.registered = true;
    const Eigen::Vector3d centre(0.6 * std::sin(a * M_PI / 180), 0.05, 0.6 * std::cos(a * M_PI / 180));
    v.cam_from_world = Eigen::Translation3d(-centre) * Eigen::Isometry3d::Identity();
    set.views.push_back(v);
  }
  return set;
}

TEST(CameraSet, AzimuthSpreadMeasuresHowFarRoundTheHeadTheViewsGo) {
  EXPECT_EQ(Ring({}).AzimuthSpreadDeg(), 0.0);
  EXPECT_EQ(Ring({10}).AzimuthSpreadDeg(), 0.0);
  EXPECT_NEAR(Ring({-20, 0, 15}).AzimuthSpreadDeg(), 35.0, 1e-9);
  // Across the back (+-180): the spread is the short way round.
  EXPECT_NEAR(Ring({170, -170}).AzimuthSpreadDeg(), 20.0, 1e-9);
  std::vector<double> all;
  for (int i = 0; i < 16; ++i) all.push_back(-180 + 22.5 * i);
  EXPECT_NEAR(Ring(all).AzimuthSpreadDeg(), 337.5, 1e-9);
  // Unregistered views do not count.
  CameraSet some = Ring({-90, 0, 90});
  some.views[2].registered = false;
  EXPECT_NEAR(some.AzimuthSpreadDeg(), 90.0, 1e-9);
  EXPECT_FALSE(some.WalksRoundTheHead());
  EXPECT_TRUE(Ring({-90, 0, 90, 180}).WalksRoundTheHead());
}

}  // namespace
}  // namespace headforge
