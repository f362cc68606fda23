// Ingest on video as people bring it, made from GRID clips with ffmpeg: a
// portrait phone video (pixels stored sideways, a rotation in the
// container), a variable frame rate, 4K, and two faces in the picture.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "capture/capture_io.h"
#include "capture/ingest.h"
#include "capture/test_util.h"
#include "core/paths.h"

namespace headforge {
namespace {

using headforge::testing::GridClip;
using headforge::testing::ScratchDir;

IngestOptions Defaults(const fs::path& video) {
  IngestOptions options;
  options.inputs = {video.string()};
  options.resolution = 192;
  ResolveIngestDefaults(DefaultDataDir(), &options);
  return options;
}

// ffmpeg with `args` (quiet, overwriting); the test fails when it fails.
void Ffmpeg(const std::string& args) {
  const std::string command = "ffmpeg -nostdin -v error -y " + args;
  ASSERT_EQ(std::system(command.c_str()), 0) << command;
}

Status Ingest(const IngestOptions& options, const fs::path& out, IngestSummary* summary, IngestedCapture* capture) {
  NullProgress progress;
  HF_RETURN_IF_ERROR(RunIngest(options, out, 2, &progress, summary));
  return ReadIngestedCapture(out, capture);
}

// Mean absolute difference of two ingested frames (8-bit levels).
double FrameDifference(const fs::path& a, const fs::path& b) {
  const cv::Mat x = cv::imread(a.string()), y = cv::imread(b.string());
  if (x.empty() || x.size() != y.size()) return 255.0;
  const cv::Scalar d = cv::mean(cv::abs(x - y) + cv::abs(y - x));
  return (d[0] + d[1] + d[2]) / 3.0;
}

TEST(RealVideo, PortraitPhoneVideoIsTurnedUpright) {
  const fs::path dir = ScratchDir();
  // The picture stored turned a quarter to the left, with the container's
  // rotation saying to turn it back, as a phone held upright writes it; and
  // the same frames stored upright, the truth.
  const std::string clip = "-i " + GridClip("bbaf2n").string() + " -t 0.6 ";
  Ffmpeg(clip + "-c:v libx264 -preset ultrafast -qp 0 -an " + (dir / "upright.mp4").string());
  Ffmpeg(clip + "-vf transpose=2 -c:v libx264 -preset ultrafast -qp 0 -an " + (dir / "sideways.mp4").string());
  Ffmpeg("-i " + (dir / "sideways.mp4").string() + " -c copy -metadata:s:v:0 rotate=90 " +
         (dir / "portrait.mp4").string());
  IngestSummary summary, truth_summary;
  IngestedCapture capture, truth;
  const Status status = Ingest(Defaults(dir / "portrait.mp4"), dir / "out", &summary, &capture);
  ASSERT_TRUE(status.ok()) << status.message();
  ASSERT_TRUE(Ingest(Defaults(dir / "upright.mp4"), dir / "truth", &truth_summary, &truth).ok());
  // The source is 360 x 288 turned upright again (stored 288 x 360) ...
  EXPECT_EQ(capture.cameras[0].source_width, 360);
  EXPECT_EQ(capture.cameras[0].source_height, 288);
  EXPECT_EQ(summary.with_landmarks, summary.kept);
  // ... and the frames are the upright clip's (a face upside down or on its
  // side is found too, and would differ by far more than 3 levels).
  ASSERT_EQ(capture.num_frames(), truth.num_frames());
  for (int i = 0; i < capture.num_frames(); i += 5)
    EXPECT_LT(FrameDifference(capture.FramePath("cam0", i), truth.FramePath("cam0", i)), 3.0) << i;
}

TEST(RealVideo, VariableFrameRateIsSampledByTimestamps) {
  const fs::path dir = ScratchDir();
  // 25 frames at 25 fps, then 25 at 12.5 fps: frame n shows at n/25 s for
  // n < 25, at 1 + (n - 25)/12.5 s after.
  Ffmpeg("-i " + GridClip("bbaf2n").string() +
         " -vf \"setpts='if(lt(N,25),N,25+2*(N-25))/(25*TB)'\" -fps_mode vfr -frames:v 50 -c:v libx264 -preset "
         "ultrafast -an " + (dir / "vfr.mp4").string());
  auto truth = [](int n) { return n < 25 ? n / 25.0 : 1.0 + (n - 25) / 12.5; };
  IngestSummary summary;
  IngestedCapture capture;
  const Status status = Ingest(Defaults(dir / "vfr.mp4"), dir / "out", &summary, &capture);
  ASSERT_TRUE(status.ok()) << status.message();
  const double mean_fps = 49 / truth(49);  // 16.8
  EXPECT_NEAR(capture.fps, mean_fps, 0.05);
  const auto& frames = capture.cameras[0].frames;
  // 17 samples in the first second; in the slower part more samples than
  // frames, each frame taken once: 24.
  ASSERT_GE(frames.size(), 40u);
  ASSERT_LE(frames.size(), 44u);
  for (size_t i = 0; i < frames.size(); ++i) {
    // Each frame's time is the time it is shown at, not its index / 25.
    EXPECT_NEAR(frames[i].time_s, truth(frames[i].source_frame), 1e-3) << i;
    // Frames a constant 1/16.8 s apart, give or take half the longer interval.
    if (i > 0) {
      EXPECT_GT(frames[i].source_frame, frames[i - 1].source_frame);
      EXPECT_NEAR(frames[i].time_s - frames[i - 1].time_s, 1.0 / mean_fps, 0.041) << i;
    }
  }
}

TEST(RealVideo, FourKVideoIsCroppedAroundTheFace) {
  const fs::path dir = ScratchDir();
  // The clip scaled 7.5 times onto a 3840 x 2160 canvas, the face right of centre.
  Ffmpeg("-i " + GridClip("bbaf2n").string() +
         " -t 0.6 -vf scale=2700:2160,pad=3840:2160:1000:0 -c:v libx264 -preset ultrafast -crf 28 -an " +
         (dir / "4k.mp4").string());
  IngestSummary summary;
  IngestedCapture capture;
  const Status status = Ingest(Defaults(dir / "4k.mp4"), dir / "out", &summary, &capture);
  ASSERT_TRUE(status.ok()) << status.message();
  const IngestedCamera& cam = capture.cameras[0];
  EXPECT_EQ(cam.source_width, 3840);
  EXPECT_EQ(cam.width, 192);
  EXPECT_EQ(summary.with_landmarks, summary.kept);
  // The crop lies on the picture, not on the padding, and scales ~10x down.
  EXPECT_GT(cam.crop_x0 + cam.crop_width / 2, 1000 + 2700 * 0.3);
  EXPECT_LT(cam.crop_x0 + cam.crop_width / 2, 1000 + 2700 * 0.7);
  EXPECT_LT(cam.crop_scale, 0.2);
}

TEST(RealVideo, TheLargestMostPersistentFaceIsFollowedAndTheChoiceSaid) {
  const fs::path dir = ScratchDir();
  // Left: another speaker at 0.6 size; right: bbaf2n at full size.
  Ffmpeg("-i " + GridClip("lbax4n").string() + " -i " + GridClip("bbaf2n").string() +
         " -t 1.2 -filter_complex \"[0:v]scale=216:172,pad=216:288:0:58[a];[a][1:v]hstack=inputs=2\" -c:v libx264 "
         "-preset ultrafast -an " + (dir / "two.mp4").string());
  IngestSummary summary;
  IngestedCapture capture;
  const Status status = Ingest(Defaults(dir / "two.mp4"), dir / "out", &summary, &capture);
  ASSERT_TRUE(status.ok()) << status.message();
  const IngestedCamera& cam = capture.cameras[0];
  EXPECT_GT(cam.crop_x0 + cam.crop_width / 2, 216 + 360 * 0.3);  // on bbaf2n
  EXPECT_GE(summary.with_landmarks, 0.9 * summary.kept);
  ASSERT_EQ(summary.faces.size(), 1u);
  EXPECT_NE(summary.faces[0].find("2 faces seen; following the largest"), std::string::npos) << summary.faces[0];
  EXPECT_NE(summary.OneLine().find("2 faces seen"), std::string::npos);
}

TEST(RealVideo, OneFaceIsNotReportedAsSeveral) {
  const fs::path dir = ScratchDir();
  IngestSummary summary;
  IngestedCapture capture;
  IngestOptions options = Defaults(GridClip("swiz3n"));
  options.max_frames = 30;
  const Status status = Ingest(options, dir / "out", &summary, &capture);
  ASSERT_TRUE(status.ok()) << status.message();
  EXPECT_TRUE(summary.faces.empty()) << summary.faces[0];
  EXPECT_EQ(summary.with_landmarks, summary.kept);
}

}  // namespace
}  // namespace headforge
