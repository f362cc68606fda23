// scripts/gpu_check.sh's dry run on the CPU (--device cpu --tiny): the GPU
// check's every step on tiny settings, from the shared tracked talking_static
// workspace, so that the script is known to work before a GPU machine is lent.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "core/fs.h"
#include "core/json_io.h"
#include "tests/run_headforge.h"
#include "tests/shared_workspace.h"

namespace headforge {
namespace {

fs::path Scratch(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("hf_gpu_check_" + name);
  fs::remove_all(dir);
  return dir;
}

bool Finite(const nlohmann::json& value) { return value.is_number() && std::isfinite(value.get<double>()); }

TEST(GpuCheck, TheDryRunOnTheCpuRunsEveryStepAndReportsItsFigures) {
  const fs::path ws = TrackedTalkingStatic();
  const std::map<std::string, std::string> before = Snapshot(ws);
  const fs::path out = Scratch("out"), work = Scratch("work");
  std::vector<std::string> args = {std::string(HEADFORGE_TEST_SOURCE_DIR) + "/scripts/gpu_check.sh",
                                   "--device", "cpu", "--tiny", "--workspace", ws.string(),
                                   "--headforge", HEADFORGE_BINARY, "--headforge-train", HEADFORGE_TRAIN_BINARY,
                                   "--work", work.string(), "--out", out.string()};
#ifdef HEADFORGE_SPLAT_BENCH
  args.insert(args.end(), {"--splat-bench", HEADFORGE_SPLAT_BENCH});
#endif
  const Result r = Headforge(args, "/bin/bash");
  nlohmann::json report;
  ASSERT_TRUE(ReadJson(out / "gpu_check.json", &report).ok()) << r.err;
  EXPECT_EQ(report["mode"], "cpu-tiny");
  std::set<std::string> names;
  for (const nlohmann::json& step : report["steps"]) {
    names.insert(step["name"].get<std::string>());
#ifndef HEADFORGE_SPLAT_BENCH
    if (step["name"] == "rasterizer") continue;  // no benchmark in this build
#endif
    EXPECT_TRUE(step["ok"].get<bool>()) << step.dump(1);
  }
  for (const char* name : {"machine", "build", "rasterizer", "gaussian_style_talking_static", "gaussian_style_grid",
                           "gan_avatar_talking_static"})
    EXPECT_TRUE(names.count(name)) << name << " did not run:\n" << report.dump(1);
  EXPECT_TRUE(report["machine"]["cores"].is_number());

  for (const nlohmann::json& step : report["steps"]) {
    if (!step.contains("model")) continue;
    SCOPED_TRACE(step["name"].get<std::string>());
    for (const char* figure : {"psnr_head", "ssim_head", "psnr_frame", "step_ms", "render_ms", "render_fps",
                               "peak_memory_mib", "pack_mib", "train_seconds"})
      EXPECT_TRUE(Finite(step[figure])) << figure << ": " << step.dump(1);
    // Tiny models learn little in a hundred steps, but more than a blank image would score.
    EXPECT_GT(step["psnr_head"].get<double>(), 10.0);
    EXPECT_GT(step["ssim_head"].get<double>(), 0.1);
    EXPECT_GT(step["held_out_views"].get<int>(), 0);
    EXPECT_GT(step["steps"].get<int>(), 0);
  }
#ifdef HEADFORGE_SPLAT_BENCH
  for (const nlohmann::json& step : report["steps"]) {
    if (step["name"] != "rasterizer") continue;
    ASSERT_EQ(step["results"].size(), 2u) << step.dump(1);
    std::set<int> channels;
    for (const nlohmann::json& row : step["results"]) {
      channels.insert(row["channels"].get<int>());
      for (const char* figure : {"forward_ms", "backward_ms", "forward_backward_ms"})
        EXPECT_TRUE(Finite(row[figure]) && row[figure].get<double>() > 0) << row.dump();
    }
    EXPECT_EQ(channels, (std::set<int>{3, 32}));
  }
#endif
  EXPECT_EQ(r.code, 0) << r.err;

  // The table, and the converter docs use, agree.
  const std::string table = Slurp(out / "gpu_check.md");
  EXPECT_NE(table.find("| gaussian-style `draft`"), std::string::npos) << table;
  EXPECT_NE(table.find("| gan-avatar `draft`"), std::string::npos) << table;
  EXPECT_NE(table.find("| 3 | 10k | 256² |"), std::string::npos) << table;
  const Result converted = Headforge({std::string(HEADFORGE_TEST_SOURCE_DIR) + "/scripts/gpu_table.py",
                                      (out / "gpu_check.json").string()}, HEADFORGE_PYTHON3);
  EXPECT_EQ(converted.code, 0) << converted.err;
  EXPECT_EQ(converted.out, table);
  EXPECT_TRUE(fs::exists(out / "gpu_check_logs.tar.gz"));
  // The shared workspace is read, not changed.
  EXPECT_EQ(Snapshot(ws), before);
}

}  // namespace
}  // namespace headforge
