// What the training tests share (train_test, export_test, decoder_test and
// model_choice_test, one binary): the tiny training options, the trained
// reference made once among the shared workspaces, and the suite that
// works on a private copy of it.
#pragma once

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <thread>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "avatar/avatar_train.h"
#include "avatar/gaussian_style/trainer.h"
#include "avatar/model_folder.h"
#include "avatar/train/dataset.h"
#include "core/camera_set.h"
#include "core/face_model.h"
#include "core/fs.h"
#include "core/json_io.h"
#include "core/mesh_renderer.h"
#include "core/paths.h"
#include "export/gaussian_ply.h"
#include "export/mesh_avatar.h"
#include "export/splat_clip.h"
#include "tests/run_headforge.h"
#include "tests/shared_workspace.h"

namespace headforge {

inline const char* const kModelDir = "models/gaussian_style";

inline fs::path Scratch(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("hf_train_" + name);
  fs::remove_all(dir);
  return dir;
}

#ifdef HEADFORGE_BROWSER_CHECKS
// A file kept in build/artefacts/ (screenshots the tests take).
inline fs::path Artefact(const std::string& name) {
  const fs::path path = fs::path(HEADFORGE_TEST_BINARY_DIR) / "artefacts" / name;
  fs::create_directories(path.parent_path());
  return path;
}
// The command that opens `page` of folder `dir` in headless Chromium
// (scripts/web/screenshot.cjs: fails on a console error or a missing file)
// and writes its screenshot to `shot`; `extra`: more of its options.
inline std::string OpenPageCommand(const fs::path& dir, const std::string& page, int width, int height, const fs::path& shot,
                            const std::string& extra = "") {
  return std::string("'") + HEADFORGE_NODE + "' '" + HEADFORGE_TEST_SOURCE_DIR + "/scripts/web/screenshot.cjs' --dir '" +
         dir.string() + "' --page " + page + " --width " + std::to_string(width) + " --height " +
         std::to_string(height) + " " + extra + " --out '" + shot.string() + "' --chromium '" + HEADFORGE_CHROMIUM +
         "'";
}
#endif

// Small enough for seconds a run: 48 px, 300 steps (half in stage 1), a
// few thousand Gaussians, triplanes of 16 (draft's 64 took a quarter of a
// run's time), a checkpoint every 20 steps.
inline std::vector<std::string> TinyOptions() {
  return {"--train-size", "48", "--steps", "300", "--canonical-fraction", "0.5", "--triplane-resolution", "16", "--init-gaussians", "1500",
          "--max-gaussians", "2500", "--densify-from", "20", "--densify-every", "20", "--densify-until", "120",
          "--eval-every", "0", "--preview-every", "0", "--log-every", "10", "--checkpoint-every", "20",
          "--max-minutes", "0", "--threads", "1"};
}

inline std::vector<std::string> TrainArgs(const fs::path& ws) {
  std::vector<std::string> args = {"train", "--workspace", ws.string()};
  for (const auto& a : TinyOptions()) args.push_back(a);
  return args;
}

// One uninterrupted tiny run on a copy of TrackedTalkingStatic(), made once
// among the shared workspaces for both of this binary's ctest entries
// (train_test and train_test_io) and every suite that starts from it; `*made`:
// that run's exit code, or its error.
inline fs::path TrainedTalkingStatic(Result* made) {
  const std::vector<std::string> options = TinyOptions();
  const fs::path tracked = TrackedTalkingStatic();
  std::vector<std::string> key = options;
  key.push_back(tracked.filename().string());
  const fs::path dir = SharedDir("talking_static_125_trained", key);
  std::string error;
  const bool ok = MakeOnce(dir, [&](const fs::path& ws) {
    CopyOf(tracked, ws);
    return Headforge(TrainArgs(ws));
  }, &error);
  made->code = ok ? 0 : 1;
  made->err = error;
  return dir;
}

// The tests that compare with that run work on a private copy of it, one
// per suite (the two ctest entries run side by side).
class TrainStage : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { CopyReference("reference"); }
  static void CopyReference(const std::string& name) { reference_ = CopyOf(TrainedTalkingStatic(&first_), Scratch(name)); }
  inline static fs::path reference_;
  inline static Result first_;
};

}  // namespace headforge
