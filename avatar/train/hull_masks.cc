#include "avatar/train/hull_masks.h"

#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <atomic>
#include <cmath>

namespace headforge {

Status HullOptions::Check() const {
  if (!(half_width > 0) || !(top > bottom) || !(voxel > 0))
    return Status::InvalidArgument("hull masks: the box needs a positive width, top above bottom and a positive voxel");
  if ((2 * half_width / voxel) * (top - bottom) / voxel * (2 * half_width / voxel) > 5e7)
    return Status::InvalidArgument("hull masks: more than 50 million grid points; give a larger voxel");
  if (!(vote > 0 && vote <= 1) || !(strict_vote > 0 && strict_vote <= 1))
    return Status::InvalidArgument("hull masks: the votes must be in (0, 1]");
  if (!(agree >= 0 && agree <= 1) || !(agree_spread >= 0 && agree_spread <= 1))
    return Status::InvalidArgument("hull masks: agree and agree_spread must be in [0, 1]");
  if (!(min_piece >= 0 && min_piece <= 1))
    return Status::InvalidArgument("hull masks: min_piece must be in [0, 1]");
  if (min_views < 1 || edge_px < 0)
    return Status::InvalidArgument("hull masks: min_views must be positive and edge_px zero or more");
  return Status::Ok();
}

namespace {

// A point of the head frame in a view's pixels (centres at integers).
struct Projection {
  explicit Projection(const SplatCamera& c) : camera(c) {}
  // False behind the camera (nearer than 1 cm).
  bool operator()(double x, double y, double z, double* u, double* v, double* depth) const {
    const auto& m = camera.cam_from_world;
    const double cx = m[0] * x + m[1] * y + m[2] * z + m[3];
    const double cy = m[4] * x + m[5] * y + m[6] * z + m[7];
    const double cz = m[8] * x + m[9] * y + m[10] * z + m[11];
    if (cz < 0.01) return false;
    *u = camera.fx * cx / cz + camera.cx;
    *v = camera.fy * cy / cz + camera.cy;
    *depth = cz;
    return true;
  }
  const SplatCamera& camera;
};

// The grid of points voted on and what is drawn of them.
class Grid {
 public:
  Grid(const HullOptions& options, const std::vector<SplatCamera>& cameras) : options_(options), cameras_(cameras) {
    nx_ = int(std::lround(2 * options.half_width / options.voxel)) + 1;
    ny_ = int(std::lround((options.top - options.bottom) / options.voxel)) + 1;
    nz_ = nx_;
    for (const SplatCamera& c : cameras) project_.emplace_back(c);
  }
  int nx() const { return nx_; }
  int ny() const { return ny_; }
  int nz() const { return nz_; }
  size_t At(int i, int j, int k) const { return size_t((int64_t(k) * ny_ + j) * nx_ + i); }
  std::array<double, 3> Point(int i, int j, int k) const {
    return {-options_.half_width + i * options_.voxel, options_.bottom + j * options_.voxel,
            -options_.half_width + k * options_.voxel};
  }

  // 1 where at least `min_views` of `voters` see the point (inside their
  // frame) and at least `share` of those have it inside their mask.
  std::vector<uint8_t> Vote(const std::vector<cv::Mat>& masks, const std::vector<int>& voters, double share,
                            int min_views) const {
    std::vector<uint8_t> kept(size_t(int64_t(nx_) * ny_ * nz_), 0);
    cv::parallel_for_(cv::Range(0, nz_), [&](const cv::Range& range) {
      for (int k = range.start; k < range.end; ++k)
        for (int j = 0; j < ny_; ++j)
          for (int i = 0; i < nx_; ++i) {
            const auto p = Point(i, j, k);
            int seen = 0, inside = 0;
            for (int v : voters) {
              double u, w, depth;
              if (!project_[size_t(v)](p[0], p[1], p[2], &u, &w, &depth)) continue;
              const int px = int(std::lround(u)), py = int(std::lround(w));
              const cv::Mat& mask = masks[size_t(v)];
              if (px < 0 || py < 0 || px >= mask.cols || py >= mask.rows) continue;
              ++seen;
              inside += mask.at<uint8_t>(py, px) >= 128;
            }
            kept[At(i, j, k)] = seen >= min_views && inside >= share * seen;
          }
    });
    return kept;
  }

  // View `v`'s silhouette of `surface`: a disc a cell across per point.
  cv::Mat Silhouette(const std::vector<std::array<double, 3>>& surface, size_t v, cv::Size size) const {
    constexpr int kShift = 4;  // sub-pixel discs: 1/16 px
    cv::Mat silhouette = cv::Mat::zeros(size, CV_8U);
    for (const auto& p : surface) {
      double u, w, depth;
      if (!project_[v](p[0], p[1], p[2], &u, &w, &depth)) continue;
      const double radius = 0.5 * options_.voxel * cameras_[v].fx / depth;
      if (u < -radius || w < -radius || u > size.width + radius || w > size.height + radius) continue;
      cv::circle(silhouette, cv::Point(int(std::lround(u * 16)), int(std::lround(w * 16))),
                 int(std::lround(std::max(0.5, radius) * 16)), cv::Scalar(255), cv::FILLED, cv::LINE_8, kShift);
    }
    // Points seen obliquely leave gaps between their discs: closed, and the
    // outlines filled (a head's silhouette has no holes).
    cv::morphologyEx(silhouette, silhouette, cv::MORPH_CLOSE, cv::getStructuringElement(cv::MORPH_ELLIPSE, {3, 3}));
    std::vector<std::vector<cv::Point>> outlines;
    cv::findContours(silhouette.clone(), outlines, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_SIMPLE);
    cv::drawContours(silhouette, outlines, -1, cv::Scalar(255), cv::FILLED);
    return silhouette;
  }

 private:
  const HullOptions& options_;
  const std::vector<SplatCamera>& cameras_;
  std::vector<Projection> project_;
  int nx_ = 0, ny_ = 0, nz_ = 0;
};

// The kept points with a neighbour that is not (or on the grid's edge): every
// ray through the shape passes one.
std::vector<std::array<double, 3>> Surface(const Grid& grid, const std::vector<uint8_t>& kept) {
  std::vector<std::array<double, 3>> surface;
  const int nx = grid.nx(), ny = grid.ny(), nz = grid.nz();
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) {
        if (!kept[grid.At(i, j, k)]) continue;
        const bool edge = i == 0 || j == 0 || k == 0 || i == nx - 1 || j == ny - 1 || k == nz - 1;
        if (edge || !kept[grid.At(i - 1, j, k)] || !kept[grid.At(i + 1, j, k)] || !kept[grid.At(i, j - 1, k)] ||
            !kept[grid.At(i, j + 1, k)] || !kept[grid.At(i, j, k - 1)] || !kept[grid.At(i, j, k + 1)])
          surface.push_back(grid.Point(i, j, k));
      }
  return surface;
}

// Drops the 6-connected pieces of the kept points under `min_share` of the
// largest and returns how many points it dropped: what a few views' mattes
// agree on apart from the person (a strip of floor at the frame's edge,
// seen by three views whose mattes took it) is small beside the head, where
// the bust, which a thin neck may leave apart at the grid's size, is not.
int64_t DropSmallPieces(const Grid& grid, double min_share, std::vector<uint8_t>* kept) {
  const int nx = grid.nx(), ny = grid.ny(), nz = grid.nz();
  std::vector<int32_t> piece(kept->size(), -1);
  std::vector<int64_t> sizes;
  std::vector<size_t> stack;
  for (size_t start = 0; start < kept->size(); ++start) {
    if (!(*kept)[start] || piece[start] >= 0) continue;
    const int32_t label = int32_t(sizes.size());
    int64_t size = 0;
    piece[start] = label;
    stack.push_back(start);
    while (!stack.empty()) {
      const size_t at = stack.back();
      stack.pop_back();
      ++size;
      const int i = int(at % size_t(nx)), j = int((at / size_t(nx)) % size_t(ny)), k = int(at / (size_t(nx) * ny));
      const int neighbours[6][3] = {{i - 1, j, k}, {i + 1, j, k}, {i, j - 1, k}, {i, j + 1, k}, {i, j, k - 1}, {i, j, k + 1}};
      for (const auto& n : neighbours) {
        if (n[0] < 0 || n[1] < 0 || n[2] < 0 || n[0] >= nx || n[1] >= ny || n[2] >= nz) continue;
        const size_t next = grid.At(n[0], n[1], n[2]);
        if ((*kept)[next] && piece[next] < 0) {
          piece[next] = label;
          stack.push_back(next);
        }
      }
    }
    sizes.push_back(size);
  }
  if (sizes.size() < 2) return 0;
  const double least = min_share * double(*std::max_element(sizes.begin(), sizes.end()));
  int64_t dropped = 0;
  for (size_t p = 0; p < kept->size(); ++p)
    if ((*kept)[p] && double(sizes[size_t(piece[p])]) < least) {
      (*kept)[p] = 0;
      ++dropped;
    }
  return dropped;
}

// IoU of a mask (>= 128) and a silhouette.
double Agreement(const cv::Mat& mask, const cv::Mat& silhouette) {
  const cv::Mat a = mask >= 128;
  return double(cv::countNonZero(a & silhouette)) / std::max(1, cv::countNonZero(a | silhouette));
}

}  // namespace

Status HullMasks(const std::vector<SplatCamera>& cameras, const std::vector<cv::Mat>& masks,
                 const std::vector<int>& voters, const HullOptions& options, std::vector<cv::Mat>* out,
                 HullStats* stats) {
  HF_RETURN_IF_ERROR(options.Check());
  if (cameras.size() != masks.size()) return Status::InvalidArgument("hull masks: one mask per camera");
  for (size_t i = 0; i < masks.size(); ++i)
    if (masks[i].type() != CV_8UC1 || masks[i].cols != cameras[i].width || masks[i].rows != cameras[i].height)
      return Status::InvalidArgument("hull masks: mask " + std::to_string(i) + " is not an 8-bit mask of its camera's size");
  for (int v : voters)
    if (v < 0 || v >= int(masks.size())) return Status::InvalidArgument("hull masks: a voter is not a view");
  if (int(voters.size()) < options.min_views)
    return Status::DataError("hull masks: " + std::to_string(voters.size()) + " views to vote, fewer than " +
                             std::to_string(options.min_views));
  Grid grid(options, cameras);
  // A first, lenient vote: a shape no few failed mattes can take apart; the
  // voters whose masks agree with its silhouette then vote again, strictly,
  // for the shape itself (a lenient vote keeps points outside it that only
  // the views seeing them edge-on rule out).
  std::vector<uint8_t> kept = grid.Vote(masks, voters, options.vote, options.min_views);
  int64_t dropped = DropSmallPieces(grid, options.min_piece, &kept);
  // Its silhouette is wider than the shape's, so each mask is judged against
  // the others' agreement with it: within `agree_spread` of their median.
  const std::vector<std::array<double, 3>> lenient = Surface(grid, kept);
  std::vector<double> agreement;
  for (int v : voters)
    agreement.push_back(Agreement(masks[size_t(v)], grid.Silhouette(lenient, size_t(v), masks[size_t(v)].size())));
  std::vector<double> sorted = agreement;
  std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
  const double median = sorted[sorted.size() / 2];
  std::vector<int> agreeing;
  for (size_t i = 0; i < voters.size(); ++i)
    if (agreement[i] >= median - options.agree_spread) agreeing.push_back(voters[i]);
  if (int(agreeing.size()) >= options.min_views) {
    std::vector<uint8_t> strict = grid.Vote(masks, agreeing, options.strict_vote, options.min_views);
    if (std::count(strict.begin(), strict.end(), 1) > 0) {
      kept = std::move(strict);
      dropped = DropSmallPieces(grid, options.min_piece, &kept);
    }
  }
  const std::vector<std::array<double, 3>> surface = Surface(grid, kept);
  const int64_t kept_points = std::count(kept.begin(), kept.end(), 1);
  if (stats) {
    stats->views = int(voters.size());
    stats->agreeing = int(agreeing.size());
    stats->kept_points = kept_points;
    stats->dropped_points = dropped;
    stats->grid_points = int64_t(kept.size());
  }
  if (kept_points == 0)
    return Status::DataError("hull masks: no point round the head is inside most views' masks (the cameras or the "
                             "masks are wrong)");

  // Each view's silhouette of the shape, then the matte's edge within
  // edge_px of it; a matte far from it (it took background, or lost the
  // face) gives way to the silhouette whole.
  out->assign(masks.size(), cv::Mat());
  std::atomic<int> replaced{0};
  const cv::Mat band =
      cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * options.edge_px + 1, 2 * options.edge_px + 1));
  cv::parallel_for_(cv::Range(0, int(masks.size())), [&](const cv::Range& range) {
    for (int v = range.start; v < range.end; ++v) {
      const cv::Mat& mask = masks[size_t(v)];
      const cv::Mat silhouette = grid.Silhouette(surface, size_t(v), mask.size());
      if (Agreement(mask, silhouette) < options.agree) {
        (*out)[size_t(v)] = silhouette;
        ++replaced;
        continue;
      }
      cv::Mat inner = silhouette, outer = silhouette;
      if (options.edge_px > 0) {
        cv::erode(silhouette, inner, band);
        cv::dilate(silhouette, outer, band);
      }
      (*out)[size_t(v)] = cv::max(cv::min(mask, outer), inner);
    }
  });
  if (stats) stats->replaced = replaced;
  return Status::Ok();
}

}  // namespace headforge
