// What the calibrate_test binary's files share (calibrate_test.cc,
// align_test.cc): the face model, a scratch folder, and a simulated scene
// ingested.
#pragma once

#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "capture/capture_io.h"
#include "capture/ingest.h"
#include "capture/simulator.h"
#include "core/fs.h"
#include "core/json_io.h"
#include "core/paths.h"

namespace headforge {

inline const fs::path kData = HEADFORGE_TEST_SHARED_DATA;

inline const FaceModel& Model() {
  static FaceModel* model = [] {
    auto* m = new FaceModel();
    EXPECT_TRUE(FaceModel::Load((kData / "ict_facekit" / "ict_face_model.h5").string(), m).ok());
    return m;
  }();
  return *model;
}

inline fs::path Scratch(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("hf_calib_" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

// Simulates `scene_text` and ingests it (no crop unless `crop` says) into
// dir/workspace. With `order` (one camera), the video is the simulated frames
// in that order, and `truth` follows it.
inline void SimulateAndIngest(const std::string& scene_text, const fs::path& dir, IngestedCapture* capture,
                              nlohmann::json* truth, const std::vector<int>& order = {},
                              const std::string& crop = "none", IngestSummary* summary_out = nullptr) {
  Scene scene;
  const Status parsed = ParseScene(scene_text, "test.toml", &scene);
  ASSERT_TRUE(parsed.ok()) << parsed.message();
  std::unique_ptr<Simulator> sim;
  ASSERT_TRUE(Simulator::Create(scene, Model(), 2, &sim).ok());
  NullProgress progress;
  ASSERT_TRUE(WriteSimulation(*sim, dir / "capture", scene_text, 0, &progress).ok());
  IngestOptions ingest;
  for (int c = 0; c < sim->num_cameras(); ++c) ingest.inputs.push_back((dir / "capture" / sim->CameraName(c)).string());
  if (!order.empty()) {
    const fs::path reordered = dir / "capture" / "reordered";
    fs::create_directories(reordered);
    for (size_t i = 0; i < order.size(); ++i)
      fs::copy_file(dir / "capture" / sim->CameraName(0) / FrameFileName(order[i]), reordered / FrameFileName(static_cast<int>(i)));
    ingest.inputs = {reordered.string()};
  }
  ingest.crop = crop;
  ingest.resolution = scene.camera.intrinsics.width;
  ingest.blur_ratio = 0.0;
  ResolveIngestDefaults(DefaultDataDir(), &ingest);
  IngestSummary summary;
  const Status ingested = RunIngest(ingest, dir / "workspace", 2, &progress, &summary);
  ASSERT_TRUE(ingested.ok()) << ingested.message();
  if (summary_out) *summary_out = summary;
  ASSERT_TRUE(ReadIngestedCapture(dir / "workspace", capture).ok());
  ASSERT_TRUE(ReadJson(dir / "capture" / "ground_truth.json", truth).ok());
  if (!order.empty()) {
    nlohmann::json frames = nlohmann::json::array();
    for (int f : order) frames.push_back((*truth)["frames"][f]);
    (*truth)["frames"] = frames;
  }
}
}  // namespace headforge
