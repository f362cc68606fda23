// `headforge pack`: a tracked workspace's training views and the resolved
// training options in one file, for headforge-train on a GPU machine that has
// LibTorch but not the rest of the stack.
#include <cstdio>

#include "avatar/avatar_train.h"
#include "avatar/model_table.h"
#include "core/log.h"
#include "pipelines/commands.h"

namespace headforge {

int PackCommand(const std::vector<std::string>& args) {
  OptionSet options;
  CommonOptions common;
  AddCommonOptions(&options, &common, /*with_workspace=*/true);
  TrainOptions train;
  AddTrainOptions(&options, &train);
  std::string out;
  options.Add("pack.out", &out, "The training pack to write (a .safetensors file).", "out",
              OptionSet::Effect::kRuntime);
  const int parsed = ParseOrExit(
      &options, args, "headforge pack --workspace DIR --out FILE [--preset standard] [train options]",
      "Writes what headforge train would train on (the tracked workspace's frames, masks,\n"
      "cameras and expressions at the training resolution, the subject's mesh, and the\n"
      "options with the preset applied) into one file. On a machine with PyTorch and a GPU,\n"
      "scripts/train_cuda.sh builds headforge-train, which trains on it with LibTorch alone:\n"
      "  headforge-train FILE --out DIR [--device cuda]\n"
      "and DIR is the model folder: for gaussian-style, copy it into\n"
      "WORKSPACE/models/gaussian_style to render and export there; for gan-avatar it holds\n"
      "the GAN alone, and on this machine\n"
      "  headforge train --workspace WORKSPACE --model gan-avatar --generator-from DIR\n"
      "adds the expression mapping (its tracker needs this build) and makes the model.");
  if (parsed >= 0) return parsed;
  if (Status s = common.Check(true); !s.ok()) return ReportFailure(s);
  if (out.empty()) return ReportFailure(Status::InvalidArgument("pack: give the file to write with --out FILE"));
  if (Status s = ApplyTrainPreset(options, &train); !s.ok()) return ReportFailure(s);
  ApplyCommonOptions(common);
  if (Status s = CheckTrackedWorkspace(common.workspace, false, "pack"); !s.ok()) return ReportFailure(s);
  if (Status s = WriteTrainPack(train, common.workspace, common.Settings().face_model, out); !s.ok())
    return ReportFailure(s);
  std::error_code ec;
  const double mib = double(fs::file_size(out, ec)) / (1 << 20);
  HF_LOG(Info) << "pack: " << out << " (" << static_cast<int>(mib + 0.5) << " MiB) for " << train.model << " ("
               << train.preset << ", " << train.data.resolution << " px, on " << train.device
               << "); train it with headforge-train " << out << " --out DIR"
               << (kGanAvatar.Is(train.model)
                       ? ", then headforge train --model " + kGanAvatar.Name() + " --generator-from DIR here"
                       : std::string());
  return kExitOk;
}

}  // namespace headforge
