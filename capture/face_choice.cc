#include "capture/face_choice.h"

#include <algorithm>
#include <cmath>

namespace headforge {

namespace {

float Iou(const cv::Rect2f& a, const cv::Rect2f& b) {
  const float inter = (a & b).area();
  const float uni = a.area() + b.area() - inter;
  return uni > 0 ? inter / uni : 0.0f;
}

}  // namespace

FaceChoice SelectFaces(const std::vector<const FrameAnalysis*>& frames) {
  struct Track {
    std::vector<std::pair<size_t, const FaceCandidate*>> members;  // (frame, face)
    double weight = 0.0;
    float MedianWidth() const {
      std::vector<float> w;
      for (const auto& m : members) w.push_back(LandmarkBounds(m.second->landmarks).width);
      std::nth_element(w.begin(), w.begin() + w.size() / 2, w.end());
      return w[w.size() / 2];
    }
  };
  constexpr size_t kMaxGap = 10;       // frames a track may go unseen and still continue
  constexpr float kMinOverlap = 0.2f;  // IoU with the track's last box
  std::vector<Track> tracks;
  for (size_t i = 0; i < frames.size(); ++i) {
    std::vector<const FaceCandidate*> candidates;
    for (const auto& c : frames[i]->faces)
      if (c.plausible) candidates.push_back(&c);
    auto weight = [](const FaceCandidate* c) {
      return c->detection.score * std::sqrt(LandmarkBounds(c->landmarks).area());
    };
    std::sort(candidates.begin(), candidates.end(),
              [&](auto* a, auto* b) { return weight(a) > weight(b); });
    std::vector<bool> continued(tracks.size(), false);
    std::vector<cv::Rect2f> taken;  // this frame's faces so far
    for (const FaceCandidate* c : candidates) {
      const cv::Rect2f box = LandmarkBounds(c->landmarks);
      // A second detection of a face already taken (the detector's
      // suppression lets some through) is not another face.
      bool duplicate = false;
      for (const cv::Rect2f& t : taken) duplicate = duplicate || Iou(box, t) > 0.5f;
      if (duplicate) continue;
      taken.push_back(box);
      int best = -1;
      float best_overlap = kMinOverlap;
      for (size_t t = 0; t < tracks.size(); ++t) {
        const auto& last = tracks[t].members.back();
        if (continued[t] || i - last.first > kMaxGap) continue;
        const float overlap = Iou(box, LandmarkBounds(last.second->landmarks));
        if (overlap > best_overlap) {
          best_overlap = overlap;
          best = static_cast<int>(t);
        }
      }
      if (best < 0) {
        best = static_cast<int>(tracks.size());
        tracks.emplace_back();
        continued.push_back(false);
      }
      continued[best] = true;
      tracks[best].members.emplace_back(i, c);
      tracks[best].weight += weight(c);
    }
  }
  FaceChoice choice;
  choice.faces.assign(frames.size(), nullptr);
  if (tracks.empty()) return choice;
  std::sort(tracks.begin(), tracks.end(), [](const Track& a, const Track& b) { return a.weight > b.weight; });
  const float width = tracks[0].MedianWidth();
  std::vector<bool> seen(frames.size(), false);
  for (size_t t = 0; t < tracks.size(); ++t) {
    bool shares_frame = false;
    for (const auto& m : tracks[t].members) shares_frame = shares_frame || seen[m.first];
    const float w = tracks[t].MedianWidth();
    if (t == 0 || (!shares_frame && w > width / 1.5f && w < width * 1.5f)) {
      for (const auto& [i, c] : tracks[t].members) {
        choice.faces[i] = c;
        seen[i] = true;
      }
    } else if (tracks[t].members.size() >= 3) {  // fewer: a stray detection, not a face worth a word
      if (choice.others++ == 0) {
        choice.other_frames = static_cast<int>(tracks[t].members.size());
        choice.other_width = w;
      }
    }
  }
  choice.followed_frames = static_cast<int>(std::count(seen.begin(), seen.end(), true));
  choice.followed_width = width;
  return choice;
}

}  // namespace headforge
