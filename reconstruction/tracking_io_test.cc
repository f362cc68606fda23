#include "reconstruction/tracking_io.h"

#include <gtest/gtest.h>

#include "core/json_io.h"

namespace headforge {
namespace {

fs::path Scratch(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("hf_tracking_io_" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

TrackingFile Example() {
  TrackingFile t;
  t.face_model = "/data/ict_face_model.h5";
  t.identity_modes = 3;
  t.identity = Eigen::Vector3d(0.5, -1.25, 2.0);
  t.expression_names = {"jawOpen", "eyeBlink_L", "mouthSmile_R"};
  t.head_held_by_cameras = true;
  t.median_residual_px = 0.78125;
  t.dropped_views = 2;
  t.landmark_embedding = "data/embedding.json";
  t.view_dependent_landmarks = true;
  t.contour_weight = 0.05;
  t.solver = "Ceres Solver Report: Iterations: 12";
  t.seconds = 4.5;
  for (int i = 0; i < 3; ++i) {
    TrackedFrame f;
    f.frame = i;
    f.head_motion = Eigen::Translation3d(0.01 * i, -0.02, 0.003) * Eigen::AngleAxisd(0.1 * i, Eigen::Vector3d::UnitY());
    f.expression = Eigen::Vector3d(0.1 * i, 1.0 / 3.0, 0.0);
    f.residual_px = 0.5 + i;
    f.landmarks = 68 - i;
    f.interpolated = i == 1;
    f.low_confidence = i == 2;
    f.why = i == 2 ? "few landmarks" : "";
    t.frames.push_back(f);
  }
  return t;
}

TEST(TrackingFile, RoundTripsEveryField) {
  const fs::path dir = Scratch("round_trip");
  const TrackingFile written = Example();
  ASSERT_TRUE(WriteTracking(written, dir / "tracking.json").ok());
  TrackingFile read;
  const Status status = ReadTracking(dir / "tracking.json", &read);
  ASSERT_TRUE(status.ok()) << status.message();
  EXPECT_EQ(read.face_model, written.face_model);
  EXPECT_EQ(read.identity_modes, 3);
  EXPECT_EQ(read.identity, written.identity);
  EXPECT_EQ(read.expression_names, written.expression_names);
  EXPECT_TRUE(read.head_held_by_cameras);
  EXPECT_EQ(read.median_residual_px, written.median_residual_px);
  EXPECT_EQ(read.dropped_views, 2);
  EXPECT_EQ(read.landmark_embedding, written.landmark_embedding);
  EXPECT_TRUE(read.view_dependent_landmarks);
  EXPECT_EQ(read.contour_weight, 0.05);
  EXPECT_EQ(read.solver, written.solver);
  EXPECT_EQ(read.seconds, 4.5);
  ASSERT_EQ(read.frames.size(), 3u);
  for (size_t i = 0; i < 3; ++i) {
    const TrackedFrame& a = read.frames[i];
    const TrackedFrame& b = written.frames[i];
    EXPECT_EQ(a.frame, b.frame);
    EXPECT_TRUE(a.head_motion.matrix().isApprox(b.head_motion.matrix(), 0.0));
    EXPECT_EQ(a.expression, b.expression);  // in expression_names' order, not the file's alphabetical one
    EXPECT_EQ(a.residual_px, b.residual_px);
    EXPECT_EQ(a.landmarks, b.landmarks);
    EXPECT_EQ(a.interpolated, b.interpolated);
    EXPECT_EQ(a.low_confidence, b.low_confidence);
    EXPECT_EQ(a.why, b.why);
  }
  EXPECT_EQ(read.Find(2), &read.frames[2]);
  EXPECT_EQ(read.Find(7), nullptr);
  // Written again, the same bytes.
  ASSERT_TRUE(WriteTracking(read, dir / "again.json").ok());
  std::string first, second;
  ASSERT_TRUE(ReadFileToString(dir / "tracking.json", &first).ok());
  ASSERT_TRUE(ReadFileToString(dir / "again.json", &second).ok());
  EXPECT_EQ(first, second);
}

TEST(TrackingFile, OlderOrNewerFilesGetAClearError) {
  const fs::path dir = Scratch("versions");
  ASSERT_TRUE(WriteTracking(Example(), dir / "tracking.json").ok());
  nlohmann::json json;
  ASSERT_TRUE(ReadJson(dir / "tracking.json", &json).ok());
  // Files from before the version field had none.
  json.erase("version");
  ASSERT_TRUE(WriteJsonAtomic(dir / "old.json", json).ok());
  TrackingFile t;
  Status status = ReadTracking(dir / "old.json", &t);
  EXPECT_EQ(status.code(), Status::Code::kDataError);
  EXPECT_NE(status.message().find("no version"), std::string::npos) << status.message();
  EXPECT_NE(status.message().find("run headforge track again"), std::string::npos) << status.message();
  json["version"] = TrackingFile::kVersion + 1;
  ASSERT_TRUE(WriteJsonAtomic(dir / "new.json", json).ok());
  status = ReadTracking(dir / "new.json", &t);
  EXPECT_EQ(status.code(), Status::Code::kDataError);
  EXPECT_NE(status.message().find("newer HeadForge"), std::string::npos) << status.message();
  // Missing: NotFound naming the stage.
  status = ReadTracking(dir / "absent.json", &t);
  EXPECT_EQ(status.code(), Status::Code::kNotFound);
  EXPECT_NE(status.message().find("run headforge track first"), std::string::npos) << status.message();
}

TEST(TrackingFile, DamagedFramesAreRefused) {
  const fs::path dir = Scratch("damaged");
  ASSERT_TRUE(WriteTracking(Example(), dir / "tracking.json").ok());
  nlohmann::json json;
  ASSERT_TRUE(ReadJson(dir / "tracking.json", &json).ok());
  json["frames"][1]["expression"].erase("jawOpen");
  ASSERT_TRUE(WriteJsonAtomic(dir / "damaged.json", json).ok());
  TrackingFile t;
  Status status = ReadTracking(dir / "damaged.json", &t);
  EXPECT_EQ(status.code(), Status::Code::kDataError);
  EXPECT_NE(status.message().find("damaged"), std::string::npos) << status.message();
  // A weight for a blendshape the file does not name.
  ASSERT_TRUE(ReadJson(dir / "tracking.json", &json).ok());
  json["frames"][0]["expression"]["tongueOut"] = 0.5;
  ASSERT_TRUE(WriteJsonAtomic(dir / "extra.json", json).ok());
  status = ReadTracking(dir / "extra.json", &t);
  EXPECT_EQ(status.code(), Status::Code::kDataError);
  // And the writer refuses frames whose weights do not match the names.
  TrackingFile bad = Example();
  bad.frames[0].expression = Eigen::VectorXd::Zero(2);
  EXPECT_FALSE(WriteTracking(bad, dir / "bad.json").ok());
}

}  // namespace
}  // namespace headforge
