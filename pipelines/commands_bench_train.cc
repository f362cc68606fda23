// `headforge bench train`: the gaussian-style avatar's ablation on one
// tracked workspace. Trains each variant (stage 1 only, stages 1+2 without
// the region loss, stages 1+2, the canonical deformation, mesh riding) with
// the same options into its own folder and prints held-out accuracy against
// training time.
#include <nlohmann/json.hpp>

#include <cstdio>

#include "avatar/avatar_render.h"
#include "avatar/avatar_train.h"
#include "core/json_io.h"
#include "core/log.h"
#include "pipelines/commands.h"

namespace headforge {
namespace {

struct Variant {
  const char* name;
  const char* what;
  void (*apply)(TrainOptions*);
};

const Variant kVariants[] = {
    {"stage1", "stage 1 only", [](TrainOptions* t) { t->deform = false; }},
    {"no-region", "stages 1+2, no region loss", [](TrainOptions* t) { t->region_weight = 0; }},
    {"full", "stages 1+2", [](TrainOptions*) {}},
    {"canonical", "stages 1+2, canonical deformation", [](TrainOptions* t) { t->mesh_riding = false; }},
    {"mesh-riding", "stages 1+2, mesh riding", [](TrainOptions* t) { t->mesh_riding = true; }},
};

}  // namespace

int BenchTrain(const std::vector<std::string>& args) {
  OptionSet options;
  CommonOptions common;
  AddCommonOptions(&options, &common, /*with_workspace=*/true);
  TrainOptions train;
  AddTrainOptions(&options, &train);
  std::vector<std::string> variants = {"stage1", "no-region", "full", "canonical"};
  std::string out, truth;
  bool json = false;
  options.Add("bench.variants", &variants, "Variants to train: stage1, no-region, full (the options as given), canonical (the paper's deformation "
              "in canonical space), mesh-riding.", "variants");
  options.Add("bench.out", &out, "Folder for the variants' models (default: WORKSPACE/bench_train); an "
                                 "interrupted variant resumes from its checkpoint there, and one trained with "
                                 "the same options is scored again, not retrained.", "out");
  options.Add("bench.truth", &truth,
              "A simulated capture of the workspace's scene with more cameras (scenes/talking_static_novel.toml): "
              "score the held-out frames from each of its cameras against its renders.",
              "truth");
  options.Add("bench.json", &json, "Print one JSON document instead of the table.", "json");
  const int parsed = ParseOrExit(
      &options, args, "headforge bench train --workspace DIR [--variants A,B] [--preset draft] [train options]",
      "Trains the gaussian-style avatar on a tracked workspace once per variant, with the same\n"
      "options (those of headforge train), and prints each variant's held-out PSNR and SSIM\n"
      "over the head and over the frame, the training views' PSNR, and the training time.");
  if (parsed >= 0) return parsed;
  if (Status s = common.Check(true); !s.ok()) return ReportFailure(s);
  if (Status s = ApplyTrainPreset(options, &train); !s.ok()) return ReportFailure(s);
  if (Status s = train.Check(); !s.ok()) return ReportFailure(s);
  std::vector<const Variant*> chosen;
  for (const std::string& name : variants) {
    const Variant* found = nullptr;
    for (const Variant& v : kVariants)
      if (name == v.name) found = &v;
    if (!found)
      return ReportFailure(Status::InvalidArgument("--variants: no variant '" + name +
                                                   "' (stage1, no-region, full, canonical, mesh-riding)"));
    chosen.push_back(found);
  }
  ApplyCommonOptions(common);
  if (json) SetLogLevel(LogLevel::kWarning);
  const fs::path root = out.empty() ? fs::path(common.workspace) / "bench_train" : fs::path(out);
  if (!json) {
    std::printf("| variant | steps | training time | Gaussians | held-out PSNR / SSIM, head | held-out PSNR / SSIM, frame "
                "| training views PSNR, head |\n|---|---|---|---|---|---|---|\n");
    std::fflush(stdout);
  }
  nlohmann::json rows = nlohmann::json::array();
  std::vector<std::string> novel_lines;
  for (const Variant* v : chosen) {
    TrainOptions t = train;
    v->apply(&t);
    const fs::path dir = root / v->name;
    // A variant trained earlier with the same options is not trained again.
    const std::string key = options.ToIni("train", true) + "variant = " + v->name + "\n";
    nlohmann::json row, saved;
    if (ReadJson(dir / "bench.json", &saved).ok() && saved.value("options", "") == key) {
      row = saved.at("row");
      HF_LOG(Info) << "bench train: " << v->name << " was trained with these options; scoring it again";
    } else {
      TrainSummary s;
      StderrProgress progress;
      if (Status status = RunTrain(t, common.workspace, common.Settings().face_model, dir, &progress, &s);
          !status.ok())
        return ReportFailure(status.WithContext(std::string("bench train: ") + v->name));
      row = {{"variant", v->name}, {"steps", s.steps}, {"seconds", s.seconds}, {"gaussians", s.gaussians},
             {"psnr_masked", s.psnr_masked}, {"ssim_masked", s.ssim_masked}, {"psnr", s.psnr_full},
             {"ssim", s.ssim_full}, {"train_psnr_masked", s.train_psnr_masked}};
      if (Status status = WriteJsonAtomic(dir / "bench.json", {{"options", key}, {"row", row}}, 1); !status.ok())
        return ReportFailure(status);
    }
    if (!truth.empty()) {
      std::vector<NovelViewScore> novel;
      if (Status status = ScoreNovelViews(common.workspace, dir, common.Settings().face_model, truth,
                                          dir / "novel_views", &novel);
          !status.ok())
        return ReportFailure(status.WithContext(std::string("bench train: ") + v->name));
      nlohmann::json cams = nlohmann::json::array();
      for (const NovelViewScore& n : novel) {
        cams.push_back({{"camera", n.camera}, {"yaw_deg", n.yaw_deg}, {"pitch_deg", n.pitch_deg}, {"views", n.views},
                        {"psnr_masked", n.psnr_masked}, {"ssim_masked", n.ssim_masked}, {"psnr", n.psnr_full}});
        char line[256];
        std::snprintf(line, sizeof(line), "| %s | %s | %+.0f° / %+.0f° | %d | %.2f dB / %.3f | %.2f dB |", v->what,
                      n.camera.c_str(), n.yaw_deg, n.pitch_deg, n.views, n.psnr_masked, n.ssim_masked, n.psnr_full);
        novel_lines.push_back(line);
      }
      row["novel_views"] = cams;
    }
    rows.push_back(row);
    if (!json) {
      std::printf("| %s | %d | %.1f min | %lld | %.2f dB / %.3f | %.2f dB / %.3f | %.2f dB |\n", v->what,
                  row["steps"].get<int>(), row["seconds"].get<double>() / 60,
                  static_cast<long long>(row["gaussians"].get<int64_t>()), row["psnr_masked"].get<double>(),
                  row["ssim_masked"].get<double>(), row["psnr"].get<double>(), row["ssim"].get<double>(),
                  row["train_psnr_masked"].get<double>());
      std::fflush(stdout);
    }
  }
  if (!json && !novel_lines.empty()) {
    std::printf("\nNovel views (held-out frames, the simulator's cameras):\n\n"
                "| variant | camera | yaw / pitch | views | PSNR / SSIM, head | PSNR, frame |\n|---|---|---|---|---|---|\n");
    for (const std::string& line : novel_lines) std::printf("%s\n", line.c_str());
  }
  if (json) std::printf("%s\n", nlohmann::json{{"workspace", common.workspace}, {"variants", rows}}.dump(1).c_str());
  return kExitOk;
}

}  // namespace headforge
