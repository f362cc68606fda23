#include "pipelines/commands.h"

#include <opencv2/core/utility.hpp>

#include <algorithm>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <iostream>

#include "avatar/model_table.h"
#include "avatar/torch_runtime.h"
#include "core/log.h"
#include "core/parallel.h"
#include "core/paths.h"
#include "pipelines/stage_table.h"

namespace headforge {

const std::vector<Command>& Commands() {
  static const std::vector<Command> commands = [] {
    std::vector<Command> list = {
        {"run", "Run every available stage on a video, resuming where an earlier run stopped.", RunCommand}};
    for (const StageEntry& stage : StageTable()) {
      list.push_back({stage.name, stage.summary + (stage.unavailable.empty() ? "" : " (not available yet)"),
                      [&stage](const std::vector<std::string>& args) { return StageCommand(stage, args); }});
    }
    const std::vector<Command> tools = {
      {"render", "Render a trained avatar's frames from any camera round the head.", RenderCommand},
      {"pack", "Write a training pack: a tracked workspace's training data for headforge-train on a GPU machine.",
       PackCommand},
      {"simulate", "Render a synthetic head capture with ground truth from a scene file.",
       SimulateCommand},
      {"status", "Show the stages of a workspace: status, wall time, summary.", StatusCommand},
      {"batch", "Many captures on a cluster (Slurm): batch submit MANIFEST, batch status DIR.", BatchCommand},
      {"embed-landmarks", "Measure where the landmark detector's points sit on the face model.",
       EmbedLandmarksCommand},
      {"face-model", "Face model tools: import-ict converts ICT-FaceKit's folder into the model file; inspect summarises one.",
       FaceModelCommand},
      {"splat-fit", "Fit a static Gaussian scene to a simulated capture; report held-out PSNR.",
       SplatFitCommand},
      {"bench", "Measure accuracy against time: bench calibrate, track, train, front-end; bench truth-workspace.", BenchCommand},
      {"version", "Print the version and the libraries it was built with.", VersionCommand},
    };
    list.insert(list.end(), tools.begin(), tools.end());
    return list;
  }();
  return commands;
}

Status CommonOptions::Check(bool needs_workspace) const {
  if (needs_workspace && workspace.empty())
    return Status::InvalidArgument("no workspace: give --workspace DIR");
  if (threads < 0) return Status::InvalidArgument("--threads must be >= 0 (0: all cores)");
  if (log_level != "debug" && log_level != "info" && log_level != "warning" &&
      log_level != "error" && log_level != "silent")
    return Status::InvalidArgument("--log-level must be debug, info, warning, error or silent");
  return Status::Ok();
}

StageSettings CommonOptions::Settings() const {
  StageSettings settings;
  settings.data_dir = data_dir;
  settings.face_model =
      face_model.empty() ? (fs::path(data_dir) / "ict_facekit" / "ict_face_model.h5").string() : face_model;
  settings.threads = threads > 0 ? threads : DefaultThreads();
  settings.workspace = workspace;
  return settings;
}

void AddCommonOptions(OptionSet* o, CommonOptions* common, bool with_workspace) {
  constexpr auto kRuntime = OptionSet::Effect::kRuntime;
  if (with_workspace)
    o->Add("workspace", &common->workspace,
           "Workspace folder holding every stage's outputs and workspace.json.", "", kRuntime);
  o->Add("threads", &common->threads, "Worker threads; 0 uses $HEADFORGE_THREADS when set, else every hardware thread.", "",
         kRuntime);
  common->data_dir = DefaultDataDir();
  o->Add("data", &common->data_dir,
         "Shared data folder (face model, detectors); $HEADFORGE_DATA overrides the built-in "
         "default.",
         "", kRuntime);
  o->Add("face_model", &common->face_model,
         "Face model (Basel-layout HDF5); default DATA/ict_facekit/ict_face_model.h5.", "face-model", kRuntime);
  o->Add("log_level", &common->log_level, "debug, info, warning, error or silent.", "log-level",
         kRuntime);
}

void ApplyCommonOptions(const CommonOptions& common) {
  const int threads = common.threads > 0 ? common.threads : DefaultThreads();
  cv::setNumThreads(threads);
  ConfigureTorchThreads(threads);
  KeepFreedTensorMemory();
  if (common.log_level == "debug") SetLogLevel(LogLevel::kDebug);
  if (common.log_level == "info") SetLogLevel(LogLevel::kInfo);
  if (common.log_level == "warning") SetLogLevel(LogLevel::kWarning);
  if (common.log_level == "error") SetLogLevel(LogLevel::kError);
  if (common.log_level == "silent") SetLogLevel(LogLevel::kSilent);
}

int ParseOrExit(OptionSet* options, const std::vector<std::string>& args, const std::string& usage,
                const std::string& description) {
  const Status status = options->Parse(args);
  if (!status.ok()) {
    std::fprintf(stderr, "headforge: %s\nUsage: %s (see --help)\n", status.message().c_str(),
                 usage.c_str());
    return kExitUsage;
  }
  if (options->help_requested()) {
    std::cout << options->Help(usage, description);
    return kExitOk;
  }
  for (const auto& key : options->unknown_config_keys())
    HF_LOG(Warning) << "config key '" << key << "' is not an option of this command; ignored";
  for (const auto& note : options->deprecation_notes()) HF_LOG(Warning) << note;
  return -1;
}

Status CheckTrackedWorkspace(const std::string& path, bool with_model, const std::string& who) {
  // A folder of a workspace's files without its manifest (headforge bench
  // truth-workspace's): its readers say what is missing.
  std::error_code ec;
  if (!Workspace::Exists(path) && fs::exists(fs::path(path) / "tracking.json", ec)) return Status::Ok();
  std::unique_ptr<Workspace> workspace;
  HF_RETURN_IF_ERROR(Workspace::Open(path, Workspace::Mode::kReadOnly, &workspace));
  HF_RETURN_IF_ERROR(RequireStagesCurrent(*workspace, {"ingest", "calibrate", "align", "track"}, who));
  if (with_model)
    if (const std::string why = workspace->OutputsOutOfDate("train"); !why.empty())
      HF_LOG(Warning) << who << ": the trained model is older than the tracked capture (" << why
                      << "); headforge train makes it again from the present one";
  return Status::Ok();
}

Status ResolveModelName(const std::string& workspace, std::string* model, const std::string& who) {
  const AvatarModel* entry = FindAnyAvatarModel(*model);
  if (!entry) return Status::Ok();
  const fs::path dir = entry->Dir(workspace);
  if (!entry->In(workspace))
    return Status::NotFound(who + ": the workspace has no " + entry->Name() + " model (no " +
                            (dir / std::string(entry->marker)).string() + "); " + entry->MadeBy(workspace) +
                            " makes it");
  *model = dir.string();
  return Status::Ok();
}

int ReportFailure(const Status& status) {
  std::fprintf(stderr, "headforge: %s\n", status.message().c_str());
  return status.code() == Status::Code::kInvalidArgument ? kExitUsage : kExitFailure;
}

namespace {

void PrintMainHelp() {
  std::printf(
      "headforge %s: turns a video of a person's head into an animatable 3D avatar.\n\n"
      "Usage: headforge <command> [options]\n"
      "       headforge <command> --help   options of one command, with defaults\n"
      "       headforge --version\n\nCommands:\n",
      HeadForgeVersion().c_str());
  int width = 0;
  for (const auto& c : Commands()) width = std::max(width, static_cast<int>(c.name.size()));
  for (const auto& c : Commands()) std::printf("  %-*s  %s\n", width, c.name.c_str(), c.summary.c_str());
  std::printf(
      "\nEvery stage reads and writes one workspace folder; a stage whose inputs and options\n"
      "are unchanged is skipped, and an interrupted run resumes. Exit codes: 0 done,\n"
      "1 failure (reason on stderr), 2 usage error.\n");
}

}  // namespace

int HeadForgeMain(int argc, char** argv) {
  std::vector<std::string> args(argv + 1, argv + argc);
  // A file grown past a size limit (ulimit -f) fails its write with EFBIG,
  // which is reported like a full disk, instead of killing the program with
  // SIGXFSZ mid-stage; programs it starts (ffmpeg, COLMAP) inherit this.
  std::signal(SIGXFSZ, SIG_IGN);
  if (args.empty() || args[0] == "--help" || args[0] == "-h" || args[0] == "help") {
    PrintMainHelp();
    return args.empty() ? kExitUsage : kExitOk;
  }
  if (args[0] == "--version" || args[0] == "-V") return VersionCommand({});
  for (const auto& c : Commands()) {
    if (args[0] != c.name) continue;
    try {
      return c.run(std::vector<std::string>(args.begin() + 1, args.end()));
    } catch (const std::exception& e) {
      std::fprintf(stderr, "headforge: %s: unexpected error: %s\n", c.name.c_str(), e.what());
      return kExitFailure;
    }
  }
  std::fprintf(stderr, "headforge: unknown command '%s' (see headforge --help)\n", args[0].c_str());
  return kExitUsage;
}

}  // namespace headforge
