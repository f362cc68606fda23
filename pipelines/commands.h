// The `headforge` command table. Each command parses its options, checks them,
// runs a testable library function and returns an exit code:
//   0 done, 1 failure (one-line reason on stderr), 2 usage error.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "core/options.h"
#include "core/stage.h"
#include "core/status.h"

namespace headforge {

constexpr int kExitOk = 0;
constexpr int kExitFailure = 1;
constexpr int kExitUsage = 2;

struct Command {
  std::string name;
  std::string summary;
  std::function<int(const std::vector<std::string>& args)> run;
};

// Every command, in the order `headforge --help` lists them: run, one per
// stage of the stage table, then the tools.
const std::vector<Command>& Commands();

// The whole program: dispatches argv[1] to its command.
int HeadForgeMain(int argc, char** argv);

// Options every workspace command shares.
struct CommonOptions {
  std::string workspace;  // the workspace folder
  int threads = 0;        // worker threads; 0 = all hardware threads
  std::string data_dir;   // the shared data folder
  std::string face_model;  // empty: DATA/ict_facekit/ict_face_model.h5
  std::string log_level = "info";

  Status Check(bool needs_workspace) const;
  // The data folder, face model and thread count resolved once for every
  // stage and command.
  StageSettings Settings() const;
};
void AddCommonOptions(OptionSet* options, CommonOptions* common, bool with_workspace);
// Applies threads and logging to the process (OpenCV, LibTorch, our logger).
void ApplyCommonOptions(const CommonOptions& common);

// Parses `args` into `options`: prints help and returns kExitOk when asked for,
// prints a usage error and returns kExitUsage on failure, else returns -1.
int ParseOrExit(OptionSet* options, const std::vector<std::string>& args, const std::string& usage,
                const std::string& description);
// Prints "headforge: <message>" on stderr and returns the exit code for `status`.
int ReportFailure(const Status& status);
// For a command that reads a workspace's tracked capture and its trained
// model (render, pack): fails when the workspace does not exist or one of
// ingest ... track is not done or out of date (RequireStagesCurrent); warns
// when `with_model` and the train stage's model is older than the tracking
// (a model may also come from elsewhere: headforge-train on a GPU machine).
// A folder with tracking.json but no manifest (bench truth-workspace's) is
// not checked.
Status CheckTrackedWorkspace(const std::string& workspace, bool with_model, const std::string& who);
// `--model NAME` for a name of the model table (trained or exported): its
// folder in `workspace`; anything else (a folder) is left as given. A model
// the workspace does not have is an error that says what makes it.
Status ResolveModelName(const std::string& workspace, std::string* model, const std::string& who);

// Command entry points (the stages' own are in stage_table.h).
int SimulateCommand(const std::vector<std::string>& args);
int EmbedLandmarksCommand(const std::vector<std::string>& args);
int FaceModelCommand(const std::vector<std::string>& args);
int BenchCommand(const std::vector<std::string>& args);
int BenchTrain(const std::vector<std::string>& args);
int BenchFrontEnd(const std::vector<std::string>& args);
int BenchDrive(const std::vector<std::string>& args);
int SplatFitCommand(const std::vector<std::string>& args);
int RenderCommand(const std::vector<std::string>& args);
int PackCommand(const std::vector<std::string>& args);
int StatusCommand(const std::vector<std::string>& args);
int VersionCommand(const std::vector<std::string>& args);
// `headforge batch submit|status|job` (pipelines/commands_batch.cc).
int BatchCommand(const std::vector<std::string>& args);

}  // namespace headforge
