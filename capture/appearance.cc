#include "capture/appearance.h"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

#include "capture/landmarks.h"
#include "capture/procedural.h"
#include "core/parallel.h"

namespace headforge {
namespace {

Eigen::Vector3f Bgr(const Eigen::Vector3f& rgb) { return Eigen::Vector3f(rgb.z(), rgb.y(), rgb.x()); }

float SmoothStep(float a, float b, float x) {
  const float t = std::clamp((x - a) / (b - a), 0.0f, 1.0f);
  return t * t * (3 - 2 * t);
}

// Distance in the x-y plane from p to the polyline through `points`.
float PolylineDistance(const Eigen::Vector2f& p, const std::vector<Eigen::Vector2f>& points) {
  float best = 1e9f;
  for (size_t i = 0; i + 1 < points.size(); ++i) {
    const Eigen::Vector2f a = points[i], ab = points[i + 1] - points[i];
    const float t = std::clamp((p - a).dot(ab) / ab.squaredNorm(), 0.0f, 1.0f);
    best = std::min(best, (a + t * ab - p).norm());
  }
  return best;
}

bool InsidePolygon(const Eigen::Vector2f& p, const std::vector<Eigen::Vector2f>& poly) {
  bool inside = false;
  for (size_t i = 0, j = poly.size() - 1; i < poly.size(); j = i++) {
    if ((poly[i].y() > p.y()) != (poly[j].y() > p.y()) &&
        p.x() < (poly[j].x() - poly[i].x()) * (p.y() - poly[i].y()) / (poly[j].y() - poly[i].y()) + poly[i].x())
      inside = !inside;
  }
  return inside;
}

// Rasterises the UV triangles of `triangles` into a map of `size` texels,
// where the texture spans u in [u0, u0 + u_span] and v in [0, 1].
std::vector<TexelHit> RasteriseUv(const FaceModel& model, const std::vector<int>& triangles, cv::Size size,
                                  float u0, float u_span) {
  Eigen::Matrix2Xf texels(2, model.uv_coords().cols());
  for (int i = 0; i < texels.cols(); ++i) {
    const Eigen::Vector2f uv = model.uv_coords().col(i);
    texels.col(i) = Eigen::Vector2f((uv.x() - u0) / u_span * size.width - 0.5f, (1.0f - uv.y()) * size.height - 0.5f);
  }
  return RasteriseTexels(texels, model.uv_triangles(), triangles, size);
}

std::vector<int> RegionTriangles(const FaceModel& model, const std::string& name) {
  std::vector<int> out;
  if (const FaceModel::Region* r = model.FindRegion(name))
    for (int t = r->first_triangle; t <= r->last_triangle; ++t) out.push_back(t);
  return out;
}

// The skin function: colour (BGR) and part at a head-frame point.
struct SkinShader {
  const Scene* scene;
  std::vector<Eigen::Vector2f> outer_lip, brow_right, brow_left;
  float lip_front_z = 0.0f;
  uint64_t seed;

  std::pair<Eigen::Vector3f, uint8_t> operator()(const Eigen::Vector3f& p) const {
    const double x = p.x(), y = p.y(), z = p.z();
    // Hair cap: above a hairline that runs over the forehead, above the ears
    // and down to the nape, frayed by noise.
    float hairline = 0.098f;
    if (z < 0.04f) hairline -= (0.04f - static_cast<float>(z)) * 1.25f;
    if (std::abs(x) > 0.068 && z < 0.05) hairline = std::min(hairline, 0.052f);
    hairline = std::max(hairline, -0.06f);
    hairline += 0.007f * static_cast<float>(Fbm3(x * 60, y * 60, z * 60, 3, seed + 11));
    const Eigen::Vector3f hair_bgr = Bgr(scene->hair);
    if (y > hairline) {
      const double strands = ValueNoise3(x * 900, y * 90, z * 900, seed + 12);
      const double clumps = Fbm3(x * 80, y * 40, z * 80, 3, seed + 13);
      return {hair_bgr * static_cast<float>(0.75 + 0.25 * strands + 0.2 * clumps), kPartHair};
    }
    Eigen::Vector3f c = Bgr(scene->skin);
    // Multi-scale variation.
    c *= static_cast<float>(1.0 + 0.10 * Fbm3(x * 25, y * 25, z * 25, 4, seed + 1) +
                            0.05 * Fbm3(x * 140, y * 140, z * 140, 3, seed + 2));
    // Pores: sparse small dark dots.
    const double pore = ValueNoise3(x * 1400, y * 1400, z * 1400, seed + 3);
    if (pore > 0.7) c *= static_cast<float>(1.0 - scene->pores * 0.6 * (pore - 0.7));
    // Freckles on the front of the face.
    const double freckle = ValueNoise3(x * 320, y * 320, z * 320, seed + 4);
    const double threshold = 1.0 - 0.35 * scene->freckles;
    if (z > 0.06 && y > -0.04 && freckle > threshold) {
      const float f = static_cast<float>(std::min(1.0, (freckle - threshold) / 0.08));
      c = c.cwiseProduct(Eigen::Vector3f(1, 1, 1) * (1 - 0.45f * f) + 0.45f * f * Eigen::Vector3f(0.55f, 0.7f, 0.95f));
    }
    const Eigen::Vector2f q(static_cast<float>(x), static_cast<float>(y));
    // Lips: inside the outer lip contour, on the front of the face.
    if (z > lip_front_z - 0.03f && InsidePolygon(q, outer_lip)) {
      c = c.cwiseProduct(Eigen::Vector3f(0.68f, 0.62f, 1.0f)) * 0.92f;
    }
    // Brows: near the brow landmark lines.
    const float brow = std::min(PolylineDistance(q, brow_right), PolylineDistance(q, brow_left));
    if (z > 0.05 && brow < 0.0045f) {
      const float f = 1.0f - SmoothStep(0.0025f, 0.0045f, brow);
      const double strands = ValueNoise3(x * 200, y * 1200, z * 200, seed + 5);
      const Eigen::Vector3f b = hair_bgr * static_cast<float>(0.8 + 0.3 * strands);
      c = (1 - 0.85f * f) * c + 0.85f * f * b;
    }
    return {c.cwiseMax(0.0f).cwiseMin(1.0f), kPartFace};
  }
};

}  // namespace

HeadAppearance MakeHeadAppearance(const FaceModel& model, const Eigen::Matrix3Xf& shape, const Scene& scene) {
  HF_CHECK(model.has_uv());
  HeadAppearance a;
  const uint64_t seed = Hash64(static_cast<uint64_t>(scene.appearance_seed));
  const int n = scene.texture_size;

  SkinShader shader;
  shader.scene = &scene;
  shader.seed = seed;
  const auto& lm = model.landmarks_ibug68();
  auto xy = [&](int i) { return Eigen::Vector2f(shape(0, lm[i]), shape(1, lm[i])); };
  for (int i = 48; i <= 59; ++i) shader.outer_lip.push_back(xy(i));
  for (int i = 17; i <= 21; ++i) shader.brow_right.push_back(xy(i) + Eigen::Vector2f(0, 0.002f));
  for (int i = 22; i <= 26; ++i) shader.brow_left.push_back(xy(i) + Eigen::Vector2f(0, 0.002f));
  shader.lip_front_z = shape(2, lm[51]);

  // Skin: tiles 0 and 1 side by side.
  const cv::Size skin_size(2 * n, n);
  std::vector<int> skin_tris = RegionTriangles(model, "face");
  const auto head = RegionTriangles(model, "head_and_neck");
  skin_tris.insert(skin_tris.end(), head.begin(), head.end());
  const auto hits = RasteriseUv(model, skin_tris, skin_size, 0.0f, 2.0f);
  cv::Mat skin(skin_size, CV_32FC3, cv::Scalar::all(0)), parts(skin_size, CV_8U, cv::Scalar(kPartFace));
  cv::Mat filled(skin_size, CV_8U, cv::Scalar(0));
  ParallelFor(skin_size.height, DefaultThreads(), [&](int y, int) {
    for (int x = 0; x < skin_size.width; ++x) {
      const TexelHit& h = hits[static_cast<size_t>(y) * skin_size.width + x];
      if (h.triangle < 0) continue;
      Eigen::Vector3f p = Eigen::Vector3f::Zero();
      for (int k = 0; k < 3; ++k) p += h.bary[k] * shape.col(model.triangles()(k, h.triangle));
      const auto [colour, part] = shader(p);
      skin.at<cv::Vec3f>(y, x) = cv::Vec3f(colour.x(), colour.y(), colour.z());
      parts.at<uint8_t>(y, x) = part;
      filled.at<uint8_t>(y, x) = 255;
    }
  });
  cv::Mat parts_filled = filled.clone();
  PadSeams(&skin, &filled, 6);
  PadSeams(&parts, &parts_filled, 6);
  a.skin.image = skin;
  a.skin_parts = parts;

  // Eyes: sclera, iris and pupil by the angle from the eyeball's forward axis.
  const auto eye_tris = RegionTriangles(model, "eyeball_left");
  const int eye_n = std::max(128, n / 2);
  const auto eye_hits = RasteriseUv(model, eye_tris, cv::Size(eye_n, eye_n), 0.0f, 1.0f);
  Eigen::Vector3f centre = Eigen::Vector3f::Zero();
  const FaceModel::Region* eyeball = model.FindRegion("eyeball_left");
  for (int v = eyeball->first_vertex; v <= eyeball->last_vertex; ++v) centre += shape.col(v);
  centre /= static_cast<float>(eyeball->last_vertex - eyeball->first_vertex + 1);
  cv::Mat eye(eye_n, eye_n, CV_32FC3, cv::Scalar::all(0));
  cv::Mat eye_filled(eye_n, eye_n, CV_8U, cv::Scalar(0));
  const Eigen::Vector3f iris = Bgr(scene.iris);
  for (int y = 0; y < eye_n; ++y) {
    for (int x = 0; x < eye_n; ++x) {
      const TexelHit& h = eye_hits[static_cast<size_t>(y) * eye_n + x];
      if (h.triangle < 0) continue;
      Eigen::Vector3f p = Eigen::Vector3f::Zero();
      for (int k = 0; k < 3; ++k) p += h.bary[k] * shape.col(model.triangles()(k, h.triangle));
      const Eigen::Vector3f d = (p - centre).normalized();
      const float angle = std::acos(std::clamp(d.z(), -1.0f, 1.0f));
      const float around = std::atan2(d.y(), d.x());
      Eigen::Vector3f c(0.9f, 0.92f, 0.95f);  // sclera
      c *= static_cast<float>(1.0 - 0.05 * ValueNoise3(p.x() * 800, p.y() * 800, p.z() * 800, seed + 20));
      if (angle < 0.44f) {
        const double streaks = ValueNoise1(around * 12.0, seed + 21);
        c = iris * static_cast<float>(0.8 + 0.3 * streaks) * (angle > 0.38f ? 0.55f : 1.0f);
      }
      if (angle < 0.16f) c = Eigen::Vector3f(0.03f, 0.03f, 0.03f);
      eye.at<cv::Vec3f>(y, x) = cv::Vec3f(c.x(), c.y(), c.z());
      eye_filled.at<uint8_t>(y, x) = 255;
    }
  }
  PadSeams(&eye, &eye_filled, 4);
  a.eye.image = eye;
  a.teeth = Bgr(scene.teeth);
  a.gums = Eigen::Vector3f(0.35f, 0.35f, 0.7f);
  a.mouth = Eigen::Vector3f(0.12f, 0.12f, 0.3f);
  a.socket = Bgr(scene.skin) * 0.35f;
  return a;
}

Mesh MakeHeadMesh(const FaceModel& model, const HeadAppearance& appearance) {
  Mesh mesh;
  mesh.triangles = model.triangles();
  mesh.uvs = model.uv_coords();
  mesh.uv_triangles = model.uv_triangles();
  enum : int16_t { kSkin = 0, kEye, kTeeth, kGums, kMouth, kSocket };
  Material skin;
  skin.texture = &appearance.skin;
  skin.u_scale = 0.5f;  // u in [0, 2] spans the atlas
  skin.part_map = &appearance.skin_parts;
  Material eye;
  eye.texture = &appearance.eye;
  auto constant = [](const Eigen::Vector3f& c) {
    Material m;
    m.colour = c;
    return m;
  };
  mesh.materials = {skin, eye, constant(appearance.teeth), constant(appearance.gums),
                    constant(appearance.mouth), constant(appearance.socket)};
  mesh.material.assign(model.num_triangles(), -1);  // hidden unless a region claims it
  const std::pair<const char*, int16_t> regions[] = {
      {"face", kSkin},        {"head_and_neck", kSkin},  {"eyeball_left", kEye},
      {"eyeball_right", kEye}, {"teeth", kTeeth},         {"gums_and_tongue", kGums},
      {"mouth_socket", kMouth}, {"eye_socket_left", kSocket}, {"eye_socket_right", kSocket}};
  for (const auto& [name, material] : regions)
    if (const FaceModel::Region* r = model.FindRegion(name))
      for (int t = r->first_triangle; t <= r->last_triangle; ++t) mesh.material[t] = material;
  return mesh;
}

Texture MakePatternTexture(int size, uint64_t seed, const Eigen::Vector3f& base_rgb) {
  // The noise is smooth at this scale: evaluate it on a coarse grid and enlarge.
  const int coarse = std::min(size, 256);
  cv::Mat small(coarse, coarse, CV_32FC3);
  const Eigen::Vector3f base = Bgr(base_rgb);
  for (int y = 0; y < coarse; ++y) {
    for (int x = 0; x < coarse; ++x) {
      const double u = static_cast<double>(x) / coarse, v = static_cast<double>(y) / coarse;
      const float n = static_cast<float>(0.75 + 0.25 * Fbm3(u * 8, v * 8, 0.5, 5, seed));
      small.at<cv::Vec3f>(y, x) = cv::Vec3f(base.x() * n, base.y() * n, base.z() * n);
    }
  }
  cv::Mat image;
  cv::resize(small, image, cv::Size(size, size), 0, 0, cv::INTER_CUBIC);
  // Shapes at every scale, from a tenth of the texture down to a few texels,
  // so that feature detectors find corners and blobs at any viewing distance.
  cv::RNG rng(seed);
  const int shapes = 90 + size * size / 4000;
  for (int i = 0; i < shapes; ++i) {
    const cv::Scalar colour(rng.uniform(0.05, 0.95), rng.uniform(0.05, 0.95), rng.uniform(0.05, 0.95));
    const cv::Point centre(rng.uniform(0, size), rng.uniform(0, size));
    const double scale = i < 90 ? rng.uniform(size / 60.0, size / 10.0) : std::exp(rng.uniform(std::log(3.0), std::log(size / 40.0)));
    const int extent = std::max(2, static_cast<int>(scale));
    switch (i % 3) {
      case 0:
        cv::rectangle(image, centre, centre + cv::Point(extent, rng.uniform(std::max(1, extent / 3), extent * 2)), colour, cv::FILLED);
        break;
      case 1:
        cv::circle(image, centre, std::max(1, extent / 2), colour, cv::FILLED, cv::LINE_AA);
        break;
      default:
        cv::line(image, centre, centre + cv::Point(rng.uniform(-extent, extent), rng.uniform(-extent, extent)) * 2,
                 colour, std::max(1, extent / 8), cv::LINE_AA);
    }
  }
  // Fine grain.
  cv::Mat grain(size, size, CV_32FC1);
  rng.fill(grain, cv::RNG::NORMAL, 0.0, 0.06);
  cv::GaussianBlur(grain, grain, cv::Size(0, 0), 0.8);
  std::vector<cv::Mat> channels;
  cv::split(image, channels);
  for (auto& c : channels) c += grain;
  cv::merge(channels, image);
  Texture t;
  t.image = image;
  return t;
}

}  // namespace headforge
