// SelectForCoverage on landmark shapes made by hand: a pose held long gets
// no more frames than a brief one, frames without the face fill the budget
// last, and a camera going round the head is sampled evenly in time.
#include "capture/frame_selection.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

namespace headforge {
namespace {

// 68 points on an ellipse round (cx, cy) `width` wide; `open` moves the
// lower half down (a mouth opening: a change of shape, not of place or size).
FaceCandidate Shape(float cx, float cy, float width, float open) {
  FaceCandidate c;
  for (int i = 0; i < 68; ++i) {
    const double a = 2 * M_PI * i / 68;
    const float y = 0.6f * width * float(std::sin(a));
    c.landmarks[size_t(i)] = cv::Point2f(cx + 0.5f * width * float(std::cos(a)), cy + y + (y > 0 ? open * width : 0));
  }
  c.plausible = true;
  return c;
}

struct Recording {
  std::vector<FrameAnalysis> frames;
  std::vector<const FrameAnalysis*> pointers;
  std::vector<const FaceCandidate*> faces;
  void Finish() {
    for (FrameAnalysis& f : frames) {
      pointers.push_back(&f);
      faces.push_back(f.faces.empty() ? nullptr : &f.faces[0]);
    }
  }
};

TEST(FrameSelection, APoseHeldLongGetsNoMoreFramesThanABriefOne) {
  // 90 frames of a closed mouth (the head drifting and growing a little,
  // which the similarity removes), then 10 of an open one.
  Recording r;
  for (int i = 0; i < 100; ++i) {
    FrameAnalysis f;
    f.sharpness = 10 + (i % 7);
    f.faces = {Shape(200 + i, 200, 100 + 0.2f * i, i < 90 ? 0.f : 0.3f)};
    r.frames.push_back(f);
  }
  r.Finish();
  const CoverageSelection s = SelectForCoverage(r.pointers, r.faces, 2, 1);
  ASSERT_EQ(s.chosen.size(), 2u);
  EXPECT_EQ(s.groups, 2u);
  EXPECT_FALSE(s.round_the_head);
  // One from each shape, not two of the 90.
  EXPECT_LT(s.chosen[0], 90u);
  EXPECT_GE(s.chosen[1], 90u);
  // The held pose's frame is the sharpest of the half of its group it was
  // chosen from: 16, the top of the cycle, or 15 (45 frames hold several of each).
  EXPECT_GE(r.frames[s.chosen[0]].sharpness, 15);
}

TEST(FrameSelection, FramesWithoutTheFaceFillTheBudgetLastSpreadInTime) {
  // A still face in 16 frames (one shape: one group), then 4 without a face.
  Recording r;
  for (int i = 0; i < 20; ++i) {
    FrameAnalysis f;
    f.sharpness = 1;
    if (i < 16) f.faces = {Shape(200, 200, 100, 0.f)};
    r.frames.push_back(f);
  }
  r.Finish();
  const CoverageSelection s = SelectForCoverage(r.pointers, r.faces, 3, 1);
  EXPECT_EQ(s.groups, 1u);
  EXPECT_EQ(s.without_face, 4u);
  ASSERT_EQ(s.chosen.size(), 3u);
  EXPECT_LT(s.chosen[0], 16u);
  EXPECT_EQ(s.chosen[1], 16u);  // faceless frames 16..19, two spread over them
  EXPECT_EQ(s.chosen[2], 18u);
}

TEST(FrameSelection, ACameraGoingRoundTheHeadIsSampledEvenlyInTime) {
  // A face in the first 60 of 100 frames: 40 % without it.
  Recording r;
  for (int i = 0; i < 100; ++i) {
    FrameAnalysis f;
    if (i < 60) f.faces = {Shape(200, 200, 100, 0.01f * i)};
    r.frames.push_back(f);
  }
  r.Finish();
  const CoverageSelection s = SelectForCoverage(r.pointers, r.faces, 5, 1);
  EXPECT_TRUE(s.round_the_head);
  EXPECT_EQ(s.groups, 0u);
  EXPECT_EQ(s.chosen, (std::vector<size_t>{0, 20, 40, 60, 80}));
}

TEST(FrameSelection, TheSameSeedChoosesTheSameFrames) {
  Recording r;
  for (int i = 0; i < 60; ++i) {
    FrameAnalysis f;
    f.sharpness = (i * 37) % 11;
    f.faces = {Shape(200, 200, 100, 0.3f * float(std::sin(0.3 * i)) + 0.3f)};
    r.frames.push_back(f);
  }
  r.Finish();
  const CoverageSelection a = SelectForCoverage(r.pointers, r.faces, 8, 3);
  const CoverageSelection b = SelectForCoverage(r.pointers, r.faces, 8, 3);
  EXPECT_EQ(a.chosen, b.chosen);
  EXPECT_LE(a.chosen.size(), 8u);
  EXPECT_GE(a.chosen.size(), 6u);  // k-means may leave a group empty, never more than a couple here
}

}  // namespace
}  // namespace headforge
