// headforge-train: trains an avatar from a training pack (`headforge pack`),
// needing LibTorch alone, for a GPU machine that has PyTorch but not the rest
// of HeadForge's stack. The output folder is what `headforge train` writes
// into WORKSPACE/models/gaussian_style; for the gan-avatar model it holds the
// GAN, to which `headforge train --generator-from` adds the expression
// mapping.
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "avatar/avatar_train.h"
#include "avatar/torch_runtime.h"
#include "core/interrupt.h"
#include "core/parallel.h"
#include "core/log.h"
#include "core/progress.h"

namespace {

constexpr int kExitOk = 0, kExitFailure = 1, kExitUsage = 2;

void PrintHelp() {
  std::printf(
      "Usage: headforge-train PACK --out DIR [--device cpu|cuda|cuda:N] [--max-minutes M]\n"
      "                       [--set FIELD=VALUE ...]\n\n"
      "Trains an avatar on a training pack written by\n"
      "  headforge pack --workspace WS --out PACK [train options, --preset ...]\n"
      "with the options recorded in it, as headforge train would on the workspace.\n"
      "DIR receives model.pt, config.json, stats.jsonl, eval.json and the previews\n"
      "(images only where the build has an image library). gaussian-style: copy DIR\n"
      "into WS/models/gaussian_style to render and export the avatar there.\n"
      "gan-avatar: DIR holds the GAN without its expression mapping (the mean latent\n"
      "draws every frame); copy it to the workspace's machine and run\n"
      "  headforge train --workspace WS --model gan-avatar --generator-from DIR\n"
      "to add the mapping there. An interrupted run (Ctrl-C, a kill) resumes from\n"
      "DIR's checkpoint when run again.\n\n"
      "  --device D        replaces the pack's device (cpu, cuda, cuda:N)\n"
      "  --max-minutes M   replaces the pack's training time limit (0: none)\n"
      "  --set F=V         replaces any recorded option, by its field name (the\n"
      "                    train options with _ for -: decoder_steps=0, steps=20000)\n"
      "  --threads N       CPU threads for tensor work (default 0: $HEADFORGE_THREADS\n"
      "                    when set, else all)\n"
      "  --log-level L     debug, info (default), warning, error, silent\n");
}

}  // namespace

int main(int argc, char** argv) {
  using namespace headforge;
  std::signal(SIGXFSZ, SIG_IGN);  // a file-size limit fails the write (EFBIG), reported, not a kill
  std::string pack, out, level = "info";
  std::vector<std::string> settings;
  int threads = 0;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    const auto value = [&](std::string* v) {
      if (i + 1 >= argc) return false;
      *v = argv[++i];
      return true;
    };
    std::string minutes;
    if (arg == "--help" || arg == "-h") {
      PrintHelp();
      return kExitOk;
    } else if (arg == "--out") {
      if (!value(&out)) break;
    } else if (arg == "--device" || arg == "--set") {
      std::string v;
      if (!value(&v)) break;
      settings.push_back(arg == "--set" ? v : "device=\"" + v + "\"");
    } else if (arg == "--log-level") {
      if (!value(&level)) break;
    } else if (arg == "--threads") {
      std::string count;
      char* end = nullptr;
      if (!value(&count) || (threads = int(std::strtol(count.c_str(), &end, 10)), *end != '\0') || threads < 0) {
        std::fprintf(stderr, "headforge-train: --threads takes a count >= 0 (0: all)\n");
        return kExitUsage;
      }
    } else if (arg == "--max-minutes") {
      char* end = nullptr;
      if (!value(&minutes) || std::strtod(minutes.c_str(), &end) < 0 || *end != '\0' || minutes.empty()) {
        std::fprintf(stderr, "headforge-train: --max-minutes takes a number of minutes >= 0\n");
        return kExitUsage;
      }
      settings.push_back("max_minutes=" + minutes);
    } else if (!arg.empty() && arg[0] != '-' && pack.empty()) {
      pack = arg;
    } else {
      std::fprintf(stderr, "headforge-train: unknown argument '%s' (see --help)\n", arg.c_str());
      return kExitUsage;
    }
  }
  if (pack.empty() || out.empty()) {
    std::fprintf(stderr, "headforge-train: give a PACK and --out DIR (see --help)\n");
    return kExitUsage;
  }
  const std::pair<const char*, LogLevel> levels[] = {{"debug", LogLevel::kDebug},     {"info", LogLevel::kInfo},
                                                     {"warning", LogLevel::kWarning}, {"error", LogLevel::kError},
                                                     {"silent", LogLevel::kSilent}};
  bool known = false;
  for (const auto& [name, l] : levels)
    if (level == name) SetLogLevel(l), known = true;
  if (!known) {
    std::fprintf(stderr, "headforge-train: --log-level must be debug, info, warning, error or silent\n");
    return kExitUsage;
  }
  ConfigureTorchThreads(threads > 0 ? threads : DefaultThreads());
  KeepFreedTensorMemory();
  InterruptScope interrupts;
  StderrProgress progress;
  TrainSummary summary;
  const Status status = TrainFromPack(pack, settings, out, &progress, &summary);
  if (!status.ok()) {
    std::fprintf(stderr, "headforge-train: %s\n", status.message().c_str());
    return status.code() == Status::Code::kInvalidArgument ? kExitUsage : kExitFailure;
  }
  HF_LOG(Info) << "headforge-train: " << summary.OneLine() << " -> " << out;
  return kExitOk;
}
