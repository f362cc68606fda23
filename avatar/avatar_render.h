// Rendering a trained avatar for callers that do not use LibTorch: any frame
// of its workspace (or of another workspace's tracking, which then drives
// it), from the frame's camera turned round the head.
#pragma once

#include <string>
#include <vector>

#include "core/fs.h"
#include "core/progress.h"
#include "core/status.h"

namespace headforge {

struct AvatarRenderOptions {
  // The model folder ("": WORKSPACE/models/gaussian_style, or models/gan_avatar
  // where only that was trained); its config.json says which model it holds.
  std::string model;
  std::string drive;            // a workspace whose tracked expressions drive the avatar ("": its own)
  // What is done to the driver's expression weights (avatar/drive_remedy.h):
  // none, relative (taken from the driver's own neutral to the avatar's
  // training mean) or relative+span (then onto the span of the avatar's
  // training expressions). Only with `drive`.
  std::string drive_remedy = "none";
  double drive_neutral_percentile = 10;  // the driver's neutral: this percentile of each weight over its take
  double drive_span_variance = 0.99;     // the span's principal components cover this fraction of the variance
  // Frames to render (of `drive` when given), as ParseFrameList reads them
  // ("110,20", "0-49", "0-124:5", "all"); empty: all.
  std::vector<std::string> frames;
  double yaw_deg = 0;           // the camera moved round the head, toward the subject's left
  double pitch_deg = 0;         // ... and up
  int resolution = 0;           // the longer side in pixels (0: as trained)
  std::string device = "cpu";
  bool held_out = false;        // the frames training never saw (own frames only)
  double orbit_deg = 0;         // > 0: frames[0] (or the first frame) from a camera swinging to +-this yaw and back
  int orbit_steps = 60;         // renders in an orbit
  bool video = false;           // one H.264 video (video_name) instead of a PNG per frame
  std::string video_name = "render.mp4";
  double fps = 25;
  bool side_by_side = false;    // render | frame | error x 4 (own frames only)
  double background = 1.0;      // grey level behind the head (gaussian-style; gan-avatar draws its own)
};

struct AvatarRenderSummary {
  int frames = 0;
  double seconds_per_frame = 0;  // pose and render, without reading or writing
  std::vector<std::string> files;
};

// A PNG render's file name, which says what was drawn so that renders into
// one folder do not replace each other: frame_000070.png from the frame's
// own camera, then what differs: _driven (by --drive's frame 70;
// _driven_relative, _driven_relative+span with a --drive-remedy),
// _side_by_side, _yaw+20_pitch+0 (the camera moved round the head),
// _orbit30_012 (an --orbit 30's render 12; `orbit_step` counts them).
std::string RenderFileName(const AvatarRenderOptions& options, int frame, int orbit_step);

// Renders the avatar trained in `workspace` (or options.model) into `out_dir`,
// one PNG a render named by RenderFileName, or one video.
Status RenderAvatarFrames(const fs::path& workspace, const std::string& face_model, const AvatarRenderOptions& options,
                          const fs::path& out_dir, Progress* progress, AvatarRenderSummary* summary);

// The avatar against a simulated capture's ground truth from cameras training
// never had: `truth` is a `headforge simulate` output of the same scene with
// more cameras, one of them named as the workspace's (the training camera).
// Each held-out frame is rendered from each of truth's cameras, placed in the
// avatar's head frame through the training camera (its estimated pose at that
// frame and its true pose give the head frame in truth's world), with the
// truth's intrinsics at the training resolution, and scored over the truth's
// head mask (grey 0.5 behind it in both images) and over the frame. Either
// model; `model_dir` empty: the one trained last.
// A camera the workspace calibrated at that instant (the training camera, a
// rig's others) is drawn through its own calibration, pose and lens, the
// lens carried through ingest's crop onto the truth's whole frame; and again
// through the truth's lens at that pose (`truth_lens`), where calibrate's
// focal error shows.
struct NovelViewScore {
  std::string camera;
  double yaw_deg = 0, pitch_deg = 0;  // its centre round the head, from the training camera's
  int views = 0;
  double psnr_masked = 0, ssim_masked = 0, psnr_full = 0;
  bool calibrated = false;  // drawn through the workspace's calibration of it
  double truth_lens_psnr_masked = 0, truth_lens_ssim_masked = 0;  // calibrated: through the truth's lens
};
Status ScoreNovelViews(const fs::path& workspace, const fs::path& model_dir, const std::string& face_model,
                       const fs::path& truth, const fs::path& write_dir, std::vector<NovelViewScore>* scores);

// The held-out frames scored over several regions, so that avatars trained
// on different masks of one video can be compared on the same pixels: the
// workspace's own masks (eval.json's figure), the face (the convex hull of
// the frame's 68 landmarks), and the masks of another workspace ingested from
// the same video with the same crop (`masks_from`, e.g. another --matte) with
// a band `band_px` wide on each side of their edge, where a matte's fringe of
// background shows as a rim. The frame is shown through `masks_from`'s masks
// (its own without one), grey 0.5 behind, as the avatar is drawn.
struct RegionScoreOptions {
  std::string model;       // the model folder ("": the one trained last)
  std::string masks_from;  // a workspace of the same video and crop ("": this one)
  int band_px = 6;         // 0: no band
  std::string write_dir;   // render | frame | error x 4 per view and region mask; "": none
};
struct RegionScore {
  std::string region;  // what it covers
  int views = 0;
  double psnr = 0, ssim = 0;
};
Status ScoreHeldOutRegions(const fs::path& workspace, const std::string& face_model, const RegionScoreOptions& options,
                           std::vector<RegionScore>* scores);

}  // namespace headforge
