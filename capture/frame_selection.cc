#include "capture/frame_selection.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <set>

namespace headforge {

CoverageSelection SelectForCoverage(const std::vector<const FrameAnalysis*>& frames,
                                    const std::vector<const FaceCandidate*>& faces, int budget, int seed) {
  // Shapes: centred, unit RMS radius, then turned onto the mean (twice).
  std::vector<size_t> with_face;
  std::vector<std::vector<double>> shapes;
  for (size_t i = 0; i < frames.size(); ++i) {
    const FaceCandidate* face = faces[i];
    if (!face) continue;
    std::vector<double> v(136);
    double cx = 0, cy = 0;
    for (const cv::Point2f& p : face->landmarks) cx += p.x / 68.0, cy += p.y / 68.0;
    double radius = 0;
    for (int j = 0; j < 68; ++j) {
      v[2 * j] = face->landmarks[j].x - cx;
      v[2 * j + 1] = face->landmarks[j].y - cy;
      radius += v[2 * j] * v[2 * j] + v[2 * j + 1] * v[2 * j + 1];
    }
    radius = std::sqrt(radius / 68.0);
    if (!(radius > 0)) continue;
    for (double& x : v) x /= radius;
    with_face.push_back(i);
    shapes.push_back(std::move(v));
  }
  std::vector<double> mean(136, 0.0);
  for (int round = 0; round < 2 && !shapes.empty(); ++round) {
    std::fill(mean.begin(), mean.end(), 0.0);
    for (const auto& v : shapes)
      for (int j = 0; j < 136; ++j) mean[j] += v[j] / shapes.size();
    for (auto& v : shapes) {
      double dot = 0, cross = 0;
      for (int j = 0; j < 68; ++j) {
        dot += v[2 * j] * mean[2 * j] + v[2 * j + 1] * mean[2 * j + 1];
        cross += v[2 * j] * mean[2 * j + 1] - v[2 * j + 1] * mean[2 * j];
      }
      const double a = std::atan2(cross, dot), c = std::cos(a), s = std::sin(a);
      for (int j = 0; j < 68; ++j) {
        const double x = v[2 * j], y = v[2 * j + 1];
        v[2 * j] = c * x - s * y;
        v[2 * j + 1] = s * x + c * y;
      }
    }
  }
  const auto distance2 = [](const std::vector<double>& a, const std::vector<double>& b) {
    double d = 0;
    for (size_t j = 0; j < a.size(); ++j) d += (a[j] - b[j]) * (a[j] - b[j]);
    return d;
  };
  std::set<size_t> chosen;  // indices into *kept
  // A quarter or more of the frames without the face: a camera going round
  // the head, whose frames COLMAP matches with their neighbours and whose
  // face says little about what they show. Chosen evenly in time instead.
  const size_t without_face = frames.size() - with_face.size();
  const bool round_the_head = 4 * without_face >= frames.size();
  size_t groups = round_the_head ? 0 : std::min<size_t>(size_t(budget), shapes.size());
  if (round_the_head)
    for (size_t r = 0; r < size_t(budget); ++r) chosen.insert(r * frames.size() / size_t(budget));
  if (groups > 0) {
    // k-means++ seeding, then Lloyd's iterations.
    std::mt19937 rng(uint32_t(seed) * 2654435761u + 17u);
    std::vector<std::vector<double>> centres = {shapes[rng() % shapes.size()]};
    std::vector<double> nearest(shapes.size(), std::numeric_limits<double>::max());
    while (centres.size() < groups) {
      double total = 0;
      for (size_t i = 0; i < shapes.size(); ++i) {
        nearest[i] = std::min(nearest[i], distance2(shapes[i], centres.back()));
        total += nearest[i];
      }
      if (!(total > 0)) break;  // every shape is a centre already (a still picture)
      double pick = std::uniform_real_distribution<double>(0, total)(rng);
      size_t i = 0;
      while (i + 1 < shapes.size() && (pick -= nearest[i]) > 0) ++i;
      centres.push_back(shapes[i]);
    }
    groups = centres.size();
    std::vector<size_t> group(shapes.size(), 0);
    for (int iteration = 0; iteration < 10; ++iteration) {
      for (size_t i = 0; i < shapes.size(); ++i) {
        double best = std::numeric_limits<double>::max();
        for (size_t g = 0; g < groups; ++g)
          if (const double d = distance2(shapes[i], centres[g]); d < best) best = d, group[i] = g;
      }
      std::vector<std::vector<double>> sums(groups, std::vector<double>(136, 0.0));
      std::vector<int> counts(groups, 0);
      for (size_t i = 0; i < shapes.size(); ++i) {
        ++counts[group[i]];
        for (int j = 0; j < 136; ++j) sums[group[i]][j] += shapes[i][j];
      }
      for (size_t g = 0; g < groups; ++g)
        if (counts[g] > 0)
          for (int j = 0; j < 136; ++j) centres[g][j] = sums[g][j] / counts[g];
    }
    // Each group's sharpest frame among its half nearest the centre.
    std::vector<std::vector<std::pair<double, size_t>>> members(groups);
    for (size_t i = 0; i < shapes.size(); ++i) members[group[i]].push_back({distance2(shapes[i], centres[group[i]]), i});
    for (auto& m : members) {
      if (m.empty()) continue;
      std::sort(m.begin(), m.end());
      size_t best = m[0].second;
      for (size_t r = 0; r < (m.size() + 1) / 2; ++r)
        if (frames[with_face[m[r].second]]->sharpness > frames[with_face[best]]->sharpness) best = m[r].second;
      chosen.insert(with_face[best]);
    }
  }
  // Frames without the face, spread in time, when the faces leave room.
  std::vector<size_t> faceless;
  for (size_t i = 0; i < frames.size(); ++i)
    if (!faces[i]) faceless.push_back(i);
  const size_t room = size_t(budget) > chosen.size() ? size_t(budget) - chosen.size() : 0;
  for (size_t r = 0; r < std::min(room, faceless.size()); ++r)
    chosen.insert(faceless[r * faceless.size() / std::min(room, faceless.size())]);
  CoverageSelection out;
  out.chosen.assign(chosen.begin(), chosen.end());
  out.groups = groups;
  out.without_face = without_face;
  out.round_the_head = round_the_head;
  return out;
}

}  // namespace headforge
