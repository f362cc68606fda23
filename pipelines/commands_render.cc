// `headforge render`: a trained avatar's frames from any camera round the head.
#include <cstdio>

#include "avatar/avatar_render.h"
#include "avatar/model_table.h"
#include "core/log.h"
#include "pipelines/commands.h"

namespace headforge {

int RenderCommand(const std::vector<std::string>& args) {
  OptionSet options;
  CommonOptions common;
  AddCommonOptions(&options, &common, /*with_workspace=*/true);
  AvatarRenderOptions render;
  std::string out, truth;
  bool score_regions = false;
  RegionScoreOptions regions;
  options.Add("render.out", &out, "Output folder (default: WORKSPACE/renders).", "out", OptionSet::Effect::kRuntime);
  options.Add("render.frames", &render.frames,
              "Frames to render: 0,10,20, a range 0-49, every 5th 0-124:5, or all (default: all).", "frames");
  options.Add("render.yaw", &render.yaw_deg, "Degrees the camera moves round the head toward the subject's left.",
              "yaw");
  options.Add("render.pitch", &render.pitch_deg, "Degrees the camera moves round the head upward.", "pitch");
  options.Add("render.resolution", &render.resolution, "The renders' longer side in pixels (0: as trained).",
              "resolution");
  options.Add("render.drive", &render.drive,
              "Another tracked workspace whose expressions drive this avatar (cross-reenactment).", "drive");
  options.Add("render.drive_remedy", &render.drive_remedy,
              "With --drive, what is done to the driver's expression weights: none (as tracked); relative (each "
              "weight minus the driver's own neutral, plus the avatar's mean over its training frames, clamped to "
              "[0, 1]); relative+span (then projected onto the span of the avatar's training expressions, their "
              "mean plus the principal components covering --drive-span-variance, and clamped again).",
              "drive-remedy");
  options.Add("render.drive_neutral_percentile", &render.drive_neutral_percentile,
              "The driver's neutral for --drive-remedy: this percentile (0-100) of each weight over the driver's "
              "take (a weight rests at its neutral and moves up from it).",
              "drive-neutral-percentile");
  options.Add("render.drive_span_variance", &render.drive_span_variance,
              "relative+span: the fraction of the avatar's training expressions' variance its span covers.",
              "drive-span-variance");
  options.Add("render.video", &render.video, "Write render.mp4 instead of one PNG per frame.", "video");
  options.Add("render.side_by_side", &render.side_by_side,
              "Each render beside its frame and the error between them (x4): render | frame | error.", "side-by-side");
  options.Add("render.held_out", &render.held_out, "Only the frames training held out.", "held-out");
  options.Add("render.orbit", &render.orbit_deg,
              "Swing the camera to +DEG and -DEG yaw round the head on the first frame (--orbit-steps renders); "
              "180 turns it all the way round.",
              "orbit");
  options.Add("render.orbit_steps", &render.orbit_steps, "Renders in an --orbit.", "orbit-steps");
  options.Add("render.background", &render.background, "Grey level behind the head, in [0, 1].", "background");
  options.Add("render.device", &render.device, "cpu, or cuda with a CUDA LibTorch.", "device");
  options.Add("render.model", &render.model,
              "The model (default: the workspace's model trained last): a name, " + AvatarModelNames(true) +
                  " (the last made by export), or a folder: a trained or exported model (export/weights), or "
                  "exported Gaussian blendshapes.",
              "model");
  options.Add("render.truth", &truth,
              "Score instead of render: a simulated capture of the workspace's scene with more cameras "
              "(scenes/talking_static_novel.toml); the held-out frames from each of its cameras against its "
              "renders, render | truth | error images into --out. A camera the workspace calibrated is drawn "
              "through its own pose and lens, and scored again through the truth's lens, where the focal "
              "length's error shows.",
              "truth");
  options.Add("render.score_regions", &score_regions,
              "Score instead of render: the held-out frames over the workspace's masks (eval.json's figure), over "
              "the face (the 68 landmarks' hull) and, with --score-masks, over another workspace's masks of the "
              "same video and a band (--band) each side of their edge, where a mask's fringe of background shows "
              "as a rim; --out gets render | frame | error images of each region.",
              "score-regions");
  options.Add("render.score_masks", &regions.masks_from,
              "With --score-regions: a workspace ingested from the same video with the same crop (another --matte, "
              "say) whose masks the frames are shown through and scored over, so that avatars trained on "
              "different masks compare on the same pixels.",
              "score-masks");
  options.Add("render.band", &regions.band_px,
              "With --score-regions: the band's width in pixels each side of the masks' edge (0: none).", "band");
  const int parsed = ParseOrExit(
      &options, args, "headforge render --workspace DIR [--frames A,B,...] [--yaw DEG] [--pitch DEG] [options]",
      "Renders the avatar trained in the workspace (headforge train) for its tracked frames, or\n"
      "driven by another workspace's tracking (--drive), from each frame's camera moved round\n"
      "the head by --yaw and --pitch. Writes PNGs (or render.mp4) and says the time per frame.");
  if (parsed >= 0) return parsed;
  if (Status s = common.Check(true); !s.ok()) return ReportFailure(s);
  if (!(render.background >= 0 && render.background <= 1))
    return ReportFailure(Status::InvalidArgument("--background must be in [0, 1]"));
  ApplyCommonOptions(common);
  if (Status s = ResolveModelName(common.workspace, &render.model, "render"); !s.ok()) return ReportFailure(s);
  if (Status s = CheckTrackedWorkspace(common.workspace, render.model.empty(), "render"); !s.ok())
    return ReportFailure(s);
  const fs::path out_dir = out.empty() ? fs::path(common.workspace) / (truth.empty() ? "renders" : "novel_views")
                                       : fs::path(out);
  if (score_regions) {
    regions.model = render.model;
    if (!out.empty()) regions.write_dir = out;
    std::vector<RegionScore> scores;
    if (Status s = ScoreHeldOutRegions(common.workspace, common.Settings().face_model, regions, &scores); !s.ok())
      return ReportFailure(s);
    std::printf("| held-out frames over | views | PSNR / SSIM |\n|---|---|---|\n");
    for (const RegionScore& r : scores)
      std::printf("| %s | %d | %.2f dB / %.3f |\n", r.region.c_str(), r.views, r.psnr, r.ssim);
    return kExitOk;
  }
  if (!truth.empty()) {
    const fs::path model_dir = render.model;  // empty: the model trained last
    std::vector<NovelViewScore> scores;
    if (Status s = ScoreNovelViews(common.workspace, model_dir, common.Settings().face_model, truth, out_dir, &scores);
        !s.ok())
      return ReportFailure(s);
    std::printf(
        "| camera | yaw / pitch | views | PSNR / SSIM, head | PSNR, frame | head, the workspace's pose through the "
        "truth's lens |\n|---|---|---|---|---|---|\n");
    for (const NovelViewScore& n : scores) {
      char truth_lens[64] = "- (not calibrated)";
      if (n.calibrated)
        std::snprintf(truth_lens, sizeof(truth_lens), "%.2f dB / %.3f", n.truth_lens_psnr_masked,
                      n.truth_lens_ssim_masked);
      std::printf("| %s | %+.0f° / %+.0f° | %d | %.2f dB / %.3f | %.2f dB | %s |\n", n.camera.c_str(), n.yaw_deg,
                  n.pitch_deg, n.views, n.psnr_masked, n.ssim_masked, n.psnr_full, truth_lens);
    }
    return kExitOk;
  }
  StderrProgress progress;
  AvatarRenderSummary summary;
  if (Status s = RenderAvatarFrames(common.workspace, common.Settings().face_model, render, out_dir, &progress, &summary);
      !s.ok())
    return ReportFailure(s);
  char per_frame[32];
  std::snprintf(per_frame, sizeof(per_frame), "%.1f", 1000 * summary.seconds_per_frame);
  HF_LOG(Info) << "render: " << summary.frames << (summary.frames == 1 ? " frame" : " frames") << " into "
               << out_dir.string() << ", " << per_frame << " ms per frame (posing and rendering)";
  return kExitOk;
}

}  // namespace headforge
