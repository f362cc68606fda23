#include "export/splat_clip.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include <nlohmann/json.hpp>

#include "capture/capture_io.h"
#include "core/json_io.h"
#include "core/log.h"
#include "core/process.h"

namespace headforge {
namespace {

std::string FrameFile(int frame, const std::string& extension) {
  char name[32];
  std::snprintf(name, sizeof(name), "frame_%06d.", frame);
  return name + extension;
}

// Converts `in` to `out` (splat-transform picks the format by the name),
// the degree-0 colour alone: the avatar has no higher harmonics.
Status Convert(const std::string& splat_transform, const fs::path& in, const fs::path& out, const fs::path& log) {
  std::vector<std::string> args = {splat_transform, "-q", "-w", in.string(), "-H", "0", out.string()};
  // SPZ version 3: the version most readers of the format take.
  if (out.extension() == ".spz") args.insert(args.end() - 1, {"--spz-version", "3"});
  int exit_code = 0;
  const Status run = RunProgram(args, log, &exit_code);
  // 127: the script started but `env` found no node to run it.
  if (run.code() == Status::Code::kNotFound || (run.ok() && exit_code == 127))
    return Status::NotFound("export: cannot run splat-transform (" + splat_transform +
                            "), which writes the clip's compact files: scripts/install_deps.sh installs it and node, "
                            "or give --clip-format ply");
  HF_RETURN_IF_ERROR(run);
  if (exit_code != 0) {
    std::string text;
    (void)ReadFileToString(log, &text);
    if (text.size() > 600) text = "..." + text.substr(text.size() - 600);
    return Status::DataError("export: splat-transform failed on " + in.filename().string() + " (exit " +
                             std::to_string(exit_code) + "): " + text);
  }
  return Status::Ok();
}

}  // namespace

Status CheckClipFormat(const std::string& format) {
  if (format != "spz" && format != "compressed.ply" && format != "ply")
    return Status::InvalidArgument("export: --clip-format must be spz, compressed.ply or ply, not '" + format + "'");
  return Status::Ok();
}

Status SplatClipOptions::Check() const {
  HF_RETURN_IF_ERROR(CheckClipFormat(format));
  if (frames.empty()) return Status::InvalidArgument("export: the clip has no frames");
  return Status::Ok();
}

GaussianCloud CloudFromSplats(const AvatarSplats& s) {
  constexpr float kShC0 = 0.28209479177387814f;
  GaussianCloud cloud;
  cloud.means = s.means;
  cloud.rotations = s.rotations;
  for (size_t i = 0; i < s.size(); ++i) {
    const float o = std::clamp(s.opacities[i], 1e-6f, 1 - 1e-6f);
    cloud.opacities.push_back(std::log(o / (1 - o)));
    for (int c = 0; c < 3; ++c) {
      cloud.log_scales.push_back(std::log(std::max(s.scales[3 * i + c], 1e-9f)));
      cloud.sh_dc.push_back((s.colours[3 * i + c] - 0.5f) / kShC0);
    }
  }
  return cloud;
}

Status WriteSplatClip(const fs::path& workspace, const fs::path& model_dir, const std::string& face_model,
                      const SplatClipOptions& options, const fs::path& out_dir, Progress* progress, SplatClip* clip) {
  HF_RETURN_IF_ERROR(options.Check());
  IngestedCapture capture;
  HF_RETURN_IF_ERROR(ReadIngestedCapture(workspace, &capture));
  const fs::path dir = out_dir / "clip";
  HF_RETURN_IF_ERROR(EnsureDirectory(dir));
  if (!options.viewer_dir.empty()) HF_RETURN_IF_ERROR(EnsureDirectory(options.viewer_dir));
  const fs::path log = out_dir / "splat_transform.log";
  SplatClip out;
  out.fps = capture.fps;
  const std::vector<IngestedFrame>& captured = capture.cameras.at(0).frames;
  int64_t viewer_bytes = 0;
  bool viewer_full = options.viewer_dir.empty();
  progress->Start("bake clip", int64_t(options.frames.size()));
  HF_RETURN_IF_ERROR(PoseAvatarFrames(
      workspace, model_dir, face_model, options.frames, [&](int frame, const AvatarSplats& splats) -> Status {
        const GaussianCloud cloud = CloudFromSplats(splats);
        const fs::path ply = dir / FrameFile(frame, "ply");
        HF_RETURN_IF_ERROR(WriteGaussianPly(ply, cloud));
        if (options.format != "ply") {
          const std::string name = FrameFile(frame, options.format);
          HF_RETURN_IF_ERROR(Convert(options.splat_transform, ply, dir / name, log));
          out.files.push_back("clip/" + name);
        } else {
          out.files.push_back("clip/" + ply.filename().string());
        }
        if (!viewer_full) {
          const fs::path copy = options.viewer_dir / FrameFile(frame, "compressed.ply");
          HF_RETURN_IF_ERROR(Convert(options.splat_transform, ply, copy, log));
          std::error_code size_error;
          const uintmax_t size = fs::file_size(copy, size_error);
          if (size_error) return Status::IoError("export: splat-transform wrote no " + copy.string());
          viewer_bytes += int64_t(size);
          if (viewer_bytes > options.viewer_bytes) {
            fs::remove(copy);
            viewer_full = true;
          } else {
            out.viewer_files.push_back(copy);
          }
        }
        if (options.format != "ply") fs::remove(ply);
        out.frames.push_back(frame);
        out.times.push_back(frame < int(captured.size()) ? captured[size_t(frame)].time_s - captured.front().time_s
                                                         : frame / std::max(capture.fps, 1.0));
        out.gaussians = int(splats.size());
        progress->Advance();
        return Status::Ok();
      }));
  std::error_code ignored;
  fs::remove(log, ignored);
  const nlohmann::json record = {
      {"version", 1},
      {"format", options.format},
      {"fps", out.fps},
      {"gaussians", out.gaussians},
      {"frames", out.frames},
      {"times_s", out.times},
      {"files", out.files},
      {"coordinates", "the avatar's head frame: metres, +y up, the face toward +z"},
      {"note", "every frame holds the same Gaussians in the same order; colour is the degree-0 coefficient alone"}};
  HF_RETURN_IF_ERROR(WriteJsonAtomic(dir / "clip.json", record, 2));
  out.files.push_back("clip/clip.json");
  progress->Finish(std::to_string(out.frames.size()) + " frames of " + std::to_string(out.gaussians) +
                   " Gaussians as " + options.format);
  if (!options.viewer_dir.empty() && out.viewer_files.size() < out.frames.size())
    HF_LOG(Warning) << "export: the viewer page plays the clip's first " << out.viewer_files.size() << " of "
                    << out.frames.size() << " frames (the page would pass " << (options.viewer_bytes >> 20)
                    << " MiB); the whole clip is in clip/";
  *clip = std::move(out);
  return Status::Ok();
}

}  // namespace headforge
