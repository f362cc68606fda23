// headforge-train: trains an avatar from a training pack (`headforge pack`),
// needing LibTorch alone, for a GPU machine that has PyTorch but not the rest
// of HeadForge's stack. The output folder is what `headforge train` writes
// into WORKSPACE/models/gaussian_style; for the gan-avatar model it holds the
// GAN, to which `headforge train --generator-from` adds the expression
// mapping.
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>
#include <vector>

#include "avatar/avatar_train.h"
#include "avatar/torch_runtime.h"
#include "avatar/train/distributed.h"
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
      "  --distributed M   auto (default): under torchrun (RANK, WORLD_SIZE, MASTER_ADDR,\n"
      "                    MASTER_PORT) or srun -n N (SLURM_PROCID, SLURM_NTASKS), train\n"
      "                    the gaussian-style model's stages 1-2 data-parallel: each\n"
      "                    rank its share of every step's views (views_per_step, one\n"
      "                    per rank by default), the gradients summed over the ranks\n"
      "                    (c10d, gloo); rank 0 writes DIR and trains stage 3. Every\n"
      "                    rank is given the same PACK and DIR. off: one process.\n"
      "  --distributed-timeout S  seconds to wait for the other ranks, at the start and\n"
      "                    at each step, before failing (default 1800: the others wait\n"
      "                    within it while rank 0 evaluates and saves; a rank that dies\n"
      "                    fails the others at once)\n"
      "  --log-level L     debug, info (default), warning, error, silent\n");
}

}  // namespace

int main(int argc, char** argv) {
  using namespace headforge;
  std::signal(SIGXFSZ, SIG_IGN);  // a file-size limit fails the write (EFBIG), reported, not a kill
  std::string pack, out, level = "info";
  std::vector<std::string> settings;
  int threads = 0;
  std::string distributed = "auto";
  double timeout_s = 1800;
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
    } else if (arg == "--distributed") {
      if (!value(&distributed)) {
        std::fprintf(stderr, "headforge-train: --distributed takes auto or off\n");
        return kExitUsage;
      }
    } else if (arg == "--distributed-timeout") {
      std::string text;
      char* end = nullptr;
      if (!value(&text) || text.empty() || (timeout_s = std::strtod(text.c_str(), &end)) <= 0 || *end != '\0') {
        std::fprintf(stderr, "headforge-train: --distributed-timeout takes a number of seconds > 0\n");
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
  DistributedSetup setup;
  if (Status s = ReadDistributedSetup(distributed, &setup); !s.ok()) {
    std::fprintf(stderr, "headforge-train: %s\n", s.message().c_str());
    return kExitUsage;
  }
  std::unique_ptr<ProcessGroup> group;
  if (setup.world > 1) {
    HF_LOG(Info) << "headforge-train: rank " << setup.rank << " of " << setup.world << " (" << setup.source
                 << "), meeting at " << setup.address << ":" << setup.port;
    if (Status s = ProcessGroup::Connect(setup, timeout_s, &group); !s.ok()) {
      std::fprintf(stderr, "headforge-train: %s\n", s.message().c_str());
      return kExitFailure;
    }
  }
  InterruptScope interrupts;
  StderrProgress progress;
  NullProgress quiet;  // ranks but 0 draw no progress bar
  TrainSummary summary;
  const Status status =
      TrainFromPack(pack, settings, out, setup.rank == 0 ? static_cast<Progress*>(&progress) : &quiet, &summary, group.get());
  if (!status.ok()) {
    std::fprintf(stderr, "headforge-train: %s%s\n", setup.world > 1 ? ("rank " + std::to_string(setup.rank) + ": ").c_str() : "",
                 status.message().c_str());
    return status.code() == Status::Code::kInvalidArgument ? kExitUsage : kExitFailure;
  }
  if (setup.rank == 0) HF_LOG(Info) << "headforge-train: " << summary.OneLine() << " -> " << out;
  return kExitOk;
}
