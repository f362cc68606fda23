// `headforge bench train`: held-out accuracy against training time on one
// tracked workspace. Trains each variant (the gaussian-style ablation: stage
// 1 only, stages 1+2 without the region loss, stages 1+2, the canonical
// deformation, mesh riding) and each rung of a ladder (steps, Gaussian
// count, or a preset as it stands) into its own folder and prints a row for
// each; the report plots the rows.
#include <nlohmann/json.hpp>

#include <cstdio>
#include <limits>

#include "avatar/avatar_render.h"
#include "avatar/avatar_train.h"
#include "avatar/model_table.h"
#include "core/json_io.h"
#include "core/log.h"
#include "pipelines/commands.h"

namespace headforge {
namespace {

struct Variant {
  const char* name;
  const char* what;
  void (*apply)(TrainOptions*);
  bool stage3 = false;  // trains the decoder (needs --decoder-steps); else stages 1 and 2 only
};

const Variant kVariants[] = {
    {"stage1", "stage 1 only", [](TrainOptions* t) { t->gaussian_style.deform = false; }},
    {"no-region", "stages 1+2, no region loss", [](TrainOptions* t) { t->gaussian_style.region_weight = 0; }},
    {"full", "stages 1+2", [](TrainOptions*) {}},
    {"canonical", "stages 1+2, canonical deformation", [](TrainOptions* t) { t->gaussian_style.mesh_riding = false; }},
    {"mesh-riding", "stages 1+2, mesh riding", [](TrainOptions* t) { t->gaussian_style.mesh_riding = true; }},
    // Scored over its own masks: set beside the others only through the
    // simulator's truth (--truth).
    {"mask-ingest", "stages 1+2, the workspace's masks", [](TrainOptions* t) { t->data.mask = "ingest"; }},
    // Stage 3 (GaussianStyle's Table 2b); they need --decoder-steps. Each
    // scores stage 2's splats beside the decoded image (eval_stage2.json).
    {"stage3", "stages 1-3", [](TrainOptions*) {}, true},
    {"stage3-no-ada", "stages 1-3, no augmentation",
     [](TrainOptions* t) { t->gaussian_style.decoder.decoder_ada = false; }, true},
    {"stage3-no-discriminator", "stages 1-3, no discriminator",
     [](TrainOptions* t) { t->gaussian_style.decoder.adversarial_weight = 0; }, true},
    {"stage3-full-tune", "stages 1-3, full-tune (no PTI, generator trained)",
     [](TrainOptions* t) { t->gaussian_style.decoder.full_tune = true; }, true},
};

// One rung of --ladder: "STEPS", "STEPS/GAUSSIANS" (the gaussian-style
// model's largest count), or a preset's name (the preset with its time
// limit). Other rungs train without a time limit: their steps set the
// schedule, which a limit would cut short.
struct Rung {
  std::string name, what;
  std::string preset;  // set for a preset rung
  int steps = 0;
  int64_t gaussians = 0;
};

Status ParseRung(const std::string& text, Rung* rung) {
  if (text == "draft" || text == "standard" || text == "high") {
    rung->name = rung->preset = text;
    rung->what = text + " preset";
    return Status::Ok();
  }
  const Status bad = Status::InvalidArgument("--ladder: '" + text +
                                             "' is not STEPS, STEPS/GAUSSIANS or a preset (draft, standard, high)");
  // A whole positive number, all of `part`.
  auto positive = [](const std::string& part, int64_t* value) {
    size_t used = 0;
    try {
      *value = std::stoll(part, &used);
    } catch (const std::exception&) {
      return false;
    }
    return used == part.size() && *value >= 1;
  };
  const size_t slash = text.find('/');
  int64_t steps = 0;
  if (!positive(text.substr(0, slash), &steps) || steps > std::numeric_limits<int>::max() ||
      (slash != std::string::npos && !positive(text.substr(slash + 1), &rung->gaussians)))
    return bad;
  rung->steps = int(steps);
  rung->name = "ladder_" + std::to_string(rung->steps) + (rung->gaussians ? "_" + std::to_string(rung->gaussians) : "");
  rung->what = std::to_string(rung->steps) + " steps" +
               (rung->gaussians ? ", at most " + std::to_string(rung->gaussians) + " Gaussians" : "");
  return Status::Ok();
}

// Each variant and rung: its folder's name, its row's label and its options.
struct Job {
  std::string name, what;
  TrainOptions options;
};

// The jobs of --variants, then those of --ladder, each with `train` as the
// variant or rung sets it.
Status MakeJobs(const OptionSet& options, const TrainOptions& train, const std::vector<std::string>& variants,
                const std::vector<std::string>& ladder, std::vector<Job>* jobs) {
  for (const std::string& name : variants) {
    const Variant* found = nullptr;
    for (const Variant& v : kVariants)
      if (name == v.name) found = &v;
    if (!found)
      return Status::InvalidArgument(
          "--variants: no variant '" + name +
          "' (stage1, no-region, full, canonical, mesh-riding, stage3, stage3-no-ada, stage3-no-discriminator, "
          "stage3-full-tune)");
    if (found->stage3 && train.gaussian_style.decoder.decoder_steps <= 0)
      return Status::InvalidArgument("--variants " + name +
                                     ": stage 3 needs --decoder-steps N (and its --prior-steps, "
                                     "--pti-steps, --decoder-resolution; docs/avatar.md)");
    jobs->push_back({found->name, found->what, train});
    // The ablation compares the variants over one budget: none stops early
    // unless asked (--patience), and none trains on fewer frames than asked.
    GaussianStyleTrainOptions& style = jobs->back().options.gaussian_style;
    if (!options.WasGiven("train.patience")) style.patience = 0;
    if (!options.WasGiven("train.validation")) style.validation = 0;
    found->apply(&jobs->back().options);
    if (!found->stage3) style.decoder.decoder_steps = 0;  // their rows are stages 1 and 2
  }
  for (const std::string& text : ladder) {
    Rung rung;
    if (Status s = ParseRung(text, &rung); !s.ok()) return s;
    Job job{rung.name, rung.what, train};
    if (!rung.preset.empty()) {
      job.options.preset = rung.preset;
      if (Status s = ApplyTrainPreset(options, &job.options); !s.ok()) return s;
    } else {
      GaussianStyleTrainOptions& style = job.options.gaussian_style;
      job.options.loop.steps = rung.steps;
      job.options.loop.max_minutes = 0;
      style.patience = 0;  // a rung is its step count: it trains every step, on every training frame
      style.validation = 0;
      if (rung.gaussians) {
        if (kGanAvatar.Is(train.model))
          return Status::InvalidArgument("--ladder: '" + text + "' gives a Gaussian count, which the " +
                                         kGanAvatar.Name() + " model has not");
        style.max_gaussians = rung.gaussians;
        style.init_gaussians = std::min<int64_t>(style.init_gaussians, rung.gaussians);
      }
    }
    if (Status s = job.options.Check(); !s.ok()) return s.WithContext("--ladder " + text);
    jobs->push_back(std::move(job));
  }
  return Status::Ok();
}

// `job`'s row: trained into `dir`, or read from there when it was trained
// with the same options.
Status TrainedRow(const OptionSet& options, const CommonOptions& common, const Job& job, const fs::path& dir,
                  nlohmann::json* row_out) {
  nlohmann::json& row = *row_out;
  const TrainOptions& t = job.options;
  // A variant trained earlier with the same options is not trained again.
  const std::string key = options.ToIni("train", true) + "variant = " + job.name + "\n";
  nlohmann::json saved;
  if (ReadJson(dir / "bench.json", &saved).ok() && saved.value("options", "") == key) {
    row = saved.at("row");
    HF_LOG(Info) << "bench train: " << job.name << " was trained with these options; scoring it again";
  } else {
    TrainSummary s;
    StderrProgress progress;
    if (Status status = RunTrain(t, common.workspace, common.Settings().face_model, dir, &progress, &s);
        !status.ok())
      return status.WithContext("bench train: " + job.name);
    row = {{"variant", job.name}, {"what", job.what}, {"model", t.model}, {"preset", t.preset},
           {"steps", s.steps}, {"seconds", s.seconds}, {"gaussians", s.gaussians},
           {"psnr_masked", s.psnr_masked}, {"ssim_masked", s.ssim_masked}, {"psnr", s.psnr_full},
           {"ssim", s.ssim_full}, {"train_psnr_masked", s.train_psnr_masked}};
    // Sharpness, render time and, with stage 3, stage 2's figures beside the decoded image's.
    nlohmann::json eval;
    if (ReadJson(dir / "eval.json", &eval).ok() && eval.contains("mean")) {
      const nlohmann::json& mean = eval.at("mean");
      row["sd"] = mean.value("sd", 0.0);
      row["sharpness_truth"] = mean.value("sharpness_truth", 0.0);
      row["render_ms"] = eval.value("render_ms", 0.0);
      if (eval.contains("stage2")) {
        const nlohmann::json& stage2 = eval.at("stage2");
        row["stage2"] = {{"psnr_masked", stage2.value("psnr_masked", 0.0)},
                         {"ssim_masked", stage2.value("ssim_masked", 0.0)},
                         {"sd", stage2.value("sd", 0.0)}};
        row["stage3_seconds"] = eval.value("stage3_seconds", 0.0);
      }
    }
    if (Status status = WriteJsonAtomic(dir / "bench.json", {{"options", key}, {"row", row}}, 1); !status.ok())
      return status;
  }
  return Status::Ok();
}

// Scores `job`'s model in `dir` on the novel views of `truth`: into `row`, and
// a table line per camera onto `novel_lines`.
Status ScoreNovel(const CommonOptions& common, const Job& job, const fs::path& dir, const std::string& truth,
                  nlohmann::json* row, std::vector<std::string>* novel_lines) {
  std::vector<NovelViewScore> novel;
  if (Status status = ScoreNovelViews(common.workspace, dir, common.Settings().face_model, truth,
                                      dir / "novel_views", &novel);
      !status.ok())
    return status.WithContext("bench train: " + job.name);
  nlohmann::json cams = nlohmann::json::array();
  for (const NovelViewScore& n : novel) {
    cams.push_back({{"camera", n.camera}, {"yaw_deg", n.yaw_deg}, {"pitch_deg", n.pitch_deg}, {"views", n.views},
                    {"psnr_masked", n.psnr_masked}, {"ssim_masked", n.ssim_masked}, {"psnr", n.psnr_full}});
    if (n.calibrated)
      cams.back()["truth_lens"] = {{"psnr_masked", n.truth_lens_psnr_masked}, {"ssim_masked", n.truth_lens_ssim_masked}};
    char line[256];
    std::snprintf(line, sizeof(line), "| %s | %s | %+.0f° / %+.0f° | %d | %.2f dB / %.3f | %.2f dB |", job.what.c_str(),
                  n.camera.c_str(), n.yaw_deg, n.pitch_deg, n.views, n.psnr_masked, n.ssim_masked, n.psnr_full);
    novel_lines->push_back(line);
  }
  (*row)["novel_views"] = cams;
  return Status::Ok();
}

// Stage 3 against stage 2 (GaussianStyle's Table 2b): SD is the render's
// mean gradient magnitude over the head minus the frame's (negative: blurrier).
void PrintStage3Table(const nlohmann::json& rows) {
  bool stage3 = false;
  for (const auto& row : rows) stage3 = stage3 || row.contains("stage2");
  if (stage3) {
    std::printf("\nStage 3 (held-out frames, over the head; SD: sharpness minus the frame's):\n\n"
                "| variant | stage 2: PSNR / SSIM, SD | stage 3: PSNR / SSIM, SD | stage 3's time | render |\n"
                "|---|---|---|---|---|\n");
    for (const auto& row : rows) {
      if (!row.contains("stage2")) continue;
      const nlohmann::json& s2 = row.at("stage2");
      const double ms = row.value("render_ms", 0.0);
      std::printf("| %s | %.2f dB / %.3f, %+.2f | %.2f dB / %.3f, %+.2f | %.1f min | %.1f ms (%.1f frames/s) |\n",
                  row.at("what").get<std::string>().c_str(), s2.value("psnr_masked", 0.0), s2.value("ssim_masked", 0.0),
                  s2.value("sd", 0.0), row.value("psnr_masked", 0.0), row.value("ssim_masked", 0.0), row.value("sd", 0.0),
                  row.value("stage3_seconds", 0.0) / 60, ms, ms > 0 ? 1000.0 / ms : 0.0);
    }
  }
}

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
  options.Add("bench.variants", &variants,
              "Variants to train: stage1, no-region, full (the options as given), canonical (the paper's deformation "
              "in canonical space), mesh-riding, mask-ingest (the workspace's masks as they are; held out over those, so "
              "compare it with the others through --truth) (these six train stages 1 and 2 only); stage3, stage3-no-ada, "
              "stage3-no-discriminator, stage3-full-tune (the paper's Table 2b: they need --decoder-steps, and print "
              "stage 2's figures beside stage 3's); the gan-avatar model has full alone (its default).",
              "variants");
  std::vector<std::string> ladder;
  options.Add("bench.ladder", &ladder,
              "Rungs to train besides the variants (alone when --variants is not given): STEPS, STEPS/GAUSSIANS, or a "
              "preset's name (draft, standard, high: the preset with its time limit); e.g. "
              "500,1000,2000,1000/20000,draft. The rungs train the options as given (the full variant) without a time "
              "limit.",
              "ladder");
  options.Add("bench.out", &out, "Folder for the variants' models (default: WORKSPACE/bench_train); an "
                                 "interrupted variant resumes from its checkpoint there, and one trained with "
                                 "the same options is scored again, not retrained.", "out");
  options.Add("bench.truth", &truth,
              "A simulated capture of the workspace's scene with more cameras (scenes/talking_static_novel.toml): "
              "score the held-out frames from each of its cameras against its renders.",
              "truth");
  options.Add("bench.json", &json, "Print one JSON document instead of the table.", "json");
  const int parsed = ParseOrExit(
      &options, args, "headforge bench train --workspace DIR [--variants A,B] [--ladder R1,R2] [--preset draft] [train options]",
      "Trains the avatar on a tracked workspace once per variant and per rung of the ladder,\n"
      "with the same options (those of headforge train), and prints each one's held-out PSNR\n"
      "and SSIM over the head and over the frame, the training views' PSNR, and the training\n"
      "time: what accuracy costs in time. The variants are the gaussian-style model's ablation;\n"
      "the ladder's rungs apply to either model. The workspace's report plots every row.");
  if (parsed >= 0) return parsed;
  if (Status s = common.Check(true); !s.ok()) return ReportFailure(s);
  if (Status s = ApplyTrainPreset(options, &train); !s.ok()) return ReportFailure(s);
  if (Status s = train.Check(); !s.ok()) return ReportFailure(s);
  // Names given one by one or comma-separated ("stage1,full").
  variants = SplitCommaList(variants);
  ladder = SplitCommaList(ladder);
  if (!options.WasGiven("bench.variants")) {
    if (!ladder.empty()) {
      variants.clear();
    } else if (kGanAvatar.Is(train.model)) {
      variants = {"full"};  // the ablation is the gaussian-style model's
    }
  }
  if (kGanAvatar.Is(train.model))
    for (const std::string& name : variants)
      if (name != "full")
        return ReportFailure(Status::InvalidArgument("--variants: '" + name + "' is a " + kGaussianStyle.Name() +
                                                     " variant; the " + kGanAvatar.Name() +
                                                     " model has 'full' and --ladder"));
  std::vector<Job> jobs;
  if (Status s = MakeJobs(options, train, variants, ladder, &jobs); !s.ok()) return ReportFailure(s);
  ApplyCommonOptions(common);
  if (json) SetLogLevel(LogLevel::kWarning);
  const fs::path root = out.empty() ? fs::path(common.workspace) / "bench_train" : fs::path(out);
  // The two models' rungs share names (draft, ladder_500): each model keeps
  // its own folders, so that a ladder of one does not retrain over the other's.
  if (kGanAvatar.Is(train.model))
    for (Job& job : jobs) job.name = "gan_" + job.name;
  if (!json) {
    std::printf("| variant | steps | training time | Gaussians | held-out PSNR / SSIM, head | held-out PSNR / SSIM, frame "
                "| training views PSNR, head |\n|---|---|---|---|---|---|---|\n");
    std::fflush(stdout);
  }
  nlohmann::json rows = nlohmann::json::array();
  std::vector<std::string> novel_lines;
  for (const Job& job : jobs) {
    const fs::path dir = root / job.name;
    nlohmann::json row;
    if (Status s = TrainedRow(options, common, job, dir, &row); !s.ok()) return ReportFailure(s);
    if (!truth.empty()) {
      if (Status s = ScoreNovel(common, job, dir, truth, &row, &novel_lines); !s.ok()) return ReportFailure(s);
    }
    rows.push_back(row);
    if (!json) {
      std::printf("| %s | %d | %.1f min | %lld | %.2f dB / %.3f | %.2f dB / %.3f | %.2f dB |\n", job.what.c_str(),
                  row["steps"].get<int>(), row["seconds"].get<double>() / 60,
                  static_cast<long long>(row["gaussians"].get<int64_t>()), row["psnr_masked"].get<double>(),
                  row["ssim_masked"].get<double>(), row["psnr"].get<double>(), row["ssim"].get<double>(),
                  row["train_psnr_masked"].get<double>());
      std::fflush(stdout);
    }
  }
  if (!json) PrintStage3Table(rows);
  if (!json && !novel_lines.empty()) {
    std::printf("\nNovel views (held-out frames, the simulator's cameras):\n\n"
                "| variant | camera | yaw / pitch | views | PSNR / SSIM, head | PSNR, frame |\n|---|---|---|---|---|---|\n");
    for (const std::string& line : novel_lines) std::printf("%s\n", line.c_str());
  }
  if (json) std::printf("%s\n", nlohmann::json{{"workspace", common.workspace}, {"variants", rows}}.dump(1).c_str());
  return kExitOk;
}

}  // namespace headforge
