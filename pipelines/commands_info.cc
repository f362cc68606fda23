// `headforge status` and `headforge version`.
#include <opencv2/core/version.hpp>

#include <cstdio>

#include "avatar/model_table.h"
#include "avatar/torch_runtime.h"
#include "calibration/colmap_tool.h"
#include "core/paths.h"
#include "core/workspace.h"
#include "pipelines/commands.h"
#include "pipelines/stage_table.h"

namespace headforge {

int StatusCommand(const std::vector<std::string>& args) {
  OptionSet options;
  std::string workspace_path, workspace_flag;
  options.AddPositional("WORKSPACE", &workspace_path, "The workspace folder.");
  options.Add("workspace", &workspace_flag, "The workspace folder, as every other command takes it.", "",
              OptionSet::Effect::kRuntime);
  const int parsed = ParseOrExit(&options, args, "headforge status WORKSPACE (or --workspace WORKSPACE)",
                                 "Prints each stage's status, wall time and summary. A stage is out of date when a stage\n"
                                 "whose outputs it read was run again after it: headforge run redoes it.");
  if (parsed >= 0) return parsed;
  if (!workspace_flag.empty() && !workspace_path.empty() && workspace_flag != workspace_path)
    return ReportFailure(Status::InvalidArgument("give one workspace, as WORKSPACE or with --workspace"));
  if (workspace_path.empty()) workspace_path = workspace_flag;
  if (workspace_path.empty()) return ReportFailure(Status::InvalidArgument("give the WORKSPACE folder"));
  std::unique_ptr<Workspace> workspace;
  if (Status s = Workspace::Open(workspace_path, Workspace::Mode::kReadOnly, &workspace); !s.ok())
    return ReportFailure(s);
  std::printf("workspace %s\n", workspace->root().c_str());
  std::printf("%-10s %-12s %10s  %-20s  %s\n", "stage", "status", "wall time", "finished", "summary");
  for (const auto& r : workspace->Stages(StageNames())) {
    std::string status = StageStatusName(r.status);
    std::string summary = r.message;
    if (workspace->WasInterrupted(r.name)) status = "interrupted";
    if (const std::string why = workspace->OutOfDate(r.name); !why.empty()) {
      status = "out of date";
      summary = "(" + why + ") " + summary;
    } else if (r.status != StageStatus::kDone && r.commit > 0) {
      // Not done now, but earlier outputs are still in place (a trained
      // model that render draws): say when those are older too.
      if (const std::string older = workspace->OutputsOutOfDate(r.name); !older.empty())
        summary += " (the outputs in place are from before: " + older + ")";
    }
    char wall[32] = "";
    if (r.status == StageStatus::kDone || r.status == StageStatus::kFailed)
      std::snprintf(wall, sizeof(wall), "%.2f s", r.wall_time_s);
    std::printf("%-10s %-12s %10s  %-20s  %s\n", r.name.c_str(), status.c_str(), wall,
                r.finished_at.c_str(), summary.c_str());
  }
  // The models render can draw, trained and exported (the model table's).
  std::vector<const AvatarModel*> present;
  for (const AvatarModel* m : AllAvatarModels())
    if (m->In(workspace->root())) present.push_back(m);
  if (!present.empty()) {
    std::printf("\nmodels (headforge render --model NAME draws one)\n");
    for (const AvatarModel* m : present)
      std::printf("%-20s  %s\n", m->Name().c_str(),
                  fs::relative(m->Dir(workspace->root()), workspace->root()).string().c_str());
  }
  return kExitOk;
}

int VersionCommand(const std::vector<std::string>& args) {
  OptionSet options;
  const int parsed = ParseOrExit(&options, args, "headforge version",
                                 "Prints the version and the libraries it was built with.");
  if (parsed >= 0) return parsed;
  std::string colmap;
  if (!ColmapVersion(DefaultColmapExecutable(), &colmap).ok()) colmap = "not found";
  std::printf("headforge %s\n", HeadForgeVersion().c_str());
  std::printf("  OpenCV %s\n", CV_VERSION);
  std::printf("  LibTorch %s\n", TorchDescription().c_str());
  std::printf("  %s (%s)\n", colmap.c_str(), DefaultColmapExecutable().c_str());
  std::printf("  data folder %s\n", DefaultDataDir().c_str());
  return kExitOk;
}

}  // namespace headforge
