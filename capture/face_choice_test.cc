// SelectFaces on detections placed by hand: which face ingest follows, and
// what it says of the others.
#include "capture/face_choice.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

namespace headforge {
namespace {

// A face's 68 points on an ellipse `width` wide round (cx, cy).
FaceCandidate Face(float cx, float cy, float width, float score = 0.9f, bool plausible = true) {
  FaceCandidate c;
  for (int i = 0; i < 68; ++i) {
    const double a = 2 * M_PI * i / 68;
    c.landmarks[size_t(i)] = cv::Point2f(cx + 0.5f * width * float(std::cos(a)), cy + 0.6f * width * float(std::sin(a)));
  }
  c.detection.box = cv::Rect2f(cx - width / 2, cy - 0.6f * width, width, 1.2f * width);
  c.detection.score = score;
  c.plausible = plausible;
  return c;
}

std::vector<const FrameAnalysis*> Pointers(const std::vector<FrameAnalysis>& frames) {
  std::vector<const FrameAnalysis*> out;
  for (const FrameAnalysis& f : frames) out.push_back(&f);
  return out;
}

TEST(FaceChoice, TheLargestMostPersistentFaceIsFollowedAndTheOtherCounted) {
  std::vector<FrameAnalysis> frames(30);
  for (size_t i = 0; i < frames.size(); ++i) {
    // A small face first in the list (a detector's order means nothing), the large one drifting right.
    frames[i].faces = {Face(80, 100, 40), Face(300 + float(i), 200, 120)};
  }
  const FaceChoice choice = SelectFaces(Pointers(frames));
  ASSERT_EQ(choice.faces.size(), frames.size());
  for (size_t i = 0; i < frames.size(); ++i) {
    ASSERT_NE(choice.faces[i], nullptr) << i;
    EXPECT_EQ(choice.faces[i], &frames[i].faces[1]) << i;
  }
  EXPECT_EQ(choice.followed_frames, 30);
  EXPECT_EQ(choice.others, 1);
  EXPECT_EQ(choice.other_frames, 30);
  EXPECT_NEAR(choice.followed_width, 120, 1);
  EXPECT_NEAR(choice.other_width, 40, 1);
}

TEST(FaceChoice, TheSameFaceBackElsewhereAfterAGapIsFollowedStrayAndImplausibleOnesAreNot) {
  std::vector<FrameAnalysis> frames(40);
  for (size_t i = 0; i < 15; ++i) frames[i].faces = {Face(200, 200, 100)};
  // Gone for 15 frames (beyond the 10 a track may skip), then back on the other side.
  for (size_t i = 30; i < 40; ++i) frames[i].faces = {Face(500, 220, 105)};
  // A stray detection of two frames, and an implausible face in every frame.
  frames[20].faces.push_back(Face(50, 50, 30));
  frames[21].faces.push_back(Face(50, 50, 30));
  for (FrameAnalysis& f : frames) f.faces.push_back(Face(400, 400, 300, 0.99f, /*plausible=*/false));
  const FaceChoice choice = SelectFaces(Pointers(frames));
  for (size_t i = 0; i < 40; ++i) {
    const bool seen = i < 15 || i >= 30;
    EXPECT_EQ(choice.faces[i] != nullptr, seen) << i;
    if (seen) {
      EXPECT_TRUE(choice.faces[i]->plausible) << i;
    }
  }
  EXPECT_EQ(choice.followed_frames, 25);
  EXPECT_EQ(choice.others, 0);  // the stray pair is too short to be worth a word
}

TEST(FaceChoice, ADuplicateDetectionOfOneFaceIsNotASecondFace) {
  std::vector<FrameAnalysis> frames(12);
  for (FrameAnalysis& f : frames) f.faces = {Face(200, 200, 100), Face(203, 201, 98, 0.5f)};
  const FaceChoice choice = SelectFaces(Pointers(frames));
  EXPECT_EQ(choice.others, 0);
  EXPECT_EQ(choice.followed_frames, 12);
  for (size_t i = 0; i < frames.size(); ++i) EXPECT_EQ(choice.faces[i], &frames[i].faces[0]);
}

TEST(FaceChoice, NoFaceAnywhereFollowsNothing) {
  std::vector<FrameAnalysis> frames(5);
  const FaceChoice choice = SelectFaces(Pointers(frames));
  ASSERT_EQ(choice.faces.size(), 5u);
  for (const FaceCandidate* f : choice.faces) EXPECT_EQ(f, nullptr);
  EXPECT_EQ(choice.followed_frames, 0);
}

}  // namespace
}  // namespace headforge
