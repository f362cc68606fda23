// alignment.json written and read back.
#include <gtest/gtest.h>

#include "calibration/align.h"
#include "core/json_io.h"

namespace headforge {
namespace {

TEST(AlignmentFile, RoundTripsWhatItHolds) {
  const fs::path dir = fs::temp_directory_path() / "hf_alignment_io";
  fs::remove_all(dir);
  fs::create_directories(dir);
  AlignResult r;
  r.head_from_world.scale = 1.0625;
  r.head_from_world.rotation = Eigen::AngleAxisd(0.4, Eigen::Vector3d(0, 1, 1).normalized()).toRotationMatrix();
  r.head_from_world.translation = Eigen::Vector3d(0.01, -0.5, 2.25);
  r.quality = SimilarityQuality::kPlanar;
  r.method = "views";
  r.landmarks_used = {17, 30, 36};
  r.residuals_mm = {1.5, 0.25, 3.75};
  r.inlier = {true, true, false};
  r.rms_mm = 2.5;
  r.median_mm = 1.5;
  r.reference_frame = 4;
  r.views_used = 12;
  r.reprojection_median_px = 1.125;
  r.face_points = 15000;
  r.surface_points = 12000;
  r.surface_median_mm = 0.75;
  r.surface_turn_deg = 2.5;
  r.surface_scale_change = -0.03;
  r.surface_note = "fitted";
  r.message = "ok";
  ASSERT_TRUE(WriteAlignment(r, dir / "alignment.json").ok());
  AlignResult read;
  const Status status = ReadAlignment(dir / "alignment.json", &read);
  ASSERT_TRUE(status.ok()) << status.message();
  EXPECT_EQ(read.head_from_world.scale, r.head_from_world.scale);
  EXPECT_TRUE(read.head_from_world.rotation.isApprox(r.head_from_world.rotation, 0.0));
  EXPECT_EQ(read.head_from_world.translation, r.head_from_world.translation);
  EXPECT_EQ(read.quality, SimilarityQuality::kPlanar);
  EXPECT_EQ(read.method, "views");
  EXPECT_EQ(read.landmarks_used, r.landmarks_used);
  EXPECT_EQ(read.residuals_mm, r.residuals_mm);
  EXPECT_EQ(read.inlier, r.inlier);
  EXPECT_EQ(read.rms_mm, 2.5);
  EXPECT_EQ(read.median_mm, 1.5);
  EXPECT_EQ(read.reference_frame, 4);
  EXPECT_EQ(read.views_used, 12);
  EXPECT_EQ(read.reprojection_median_px, 1.125);
  EXPECT_EQ(read.face_points, 15000);
  EXPECT_EQ(read.surface_points, 12000);
  EXPECT_EQ(read.surface_median_mm, 0.75);
  EXPECT_EQ(read.surface_turn_deg, 2.5);
  EXPECT_EQ(read.surface_scale_change, -0.03);
  EXPECT_EQ(read.surface_note, "fitted");
  EXPECT_EQ(read.message, "ok");
  ASSERT_TRUE(WriteAlignment(read, dir / "again.json").ok());
  std::string first, second;
  ASSERT_TRUE(ReadFileToString(dir / "alignment.json", &first).ok());
  ASSERT_TRUE(ReadFileToString(dir / "again.json", &second).ok());
  EXPECT_EQ(first, second);

  nlohmann::json json;
  ASSERT_TRUE(ReadJson(dir / "alignment.json", &json).ok());
  json["version"] = kAlignmentVersion + 1;
  ASSERT_TRUE(WriteJsonAtomic(dir / "newer.json", json).ok());
  const Status newer = ReadAlignment(dir / "newer.json", &read);
  EXPECT_EQ(newer.code(), Status::Code::kDataError);
  EXPECT_NE(newer.message().find("run headforge align again"), std::string::npos) << newer.message();
}

}  // namespace
}  // namespace headforge
