#include "core/mesh_renderer.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include <opencv2/imgproc.hpp>

#include "core/parallel.h"
#include "core/status.h"

namespace headforge {

Eigen::Vector2d PinholeCamera::Project(const Eigen::Vector3d& world, double* depth) const {
  const Eigen::Vector3d p = cam_from_world * world;
  if (depth) *depth = p.z();
  return Eigen::Vector2d(fx * p.x() / p.z() + cx, fy * p.y() / p.z() + cy);
}

Eigen::Isometry3d LookAt(const Eigen::Vector3d& eye, const Eigen::Vector3d& target,
                         const Eigen::Vector3d& up) {
  const Eigen::Vector3d z = (target - eye).normalized();      // forward
  Eigen::Vector3d x = z.cross(up);                             // image right ( = forward x up)
  if (x.norm() < 1e-9) x = z.cross(Eigen::Vector3d::UnitX());  // looking along `up`
  x.normalize();
  const Eigen::Vector3d y = z.cross(x);                        // image down
  Eigen::Matrix3d world_from_cam_r;
  world_from_cam_r << x, y, z;
  Eigen::Isometry3d world_from_cam = Eigen::Isometry3d::Identity();
  world_from_cam.linear() = world_from_cam_r;
  world_from_cam.translation() = eye;
  return world_from_cam.inverse();
}

Eigen::Vector3f Texture::Sample(float u, float v) const {
  const int w = image.cols, h = image.rows;
  const float x = (u - std::floor(u)) * w - 0.5f;
  const float y = (1.0f - (v - std::floor(v))) * h - 0.5f;
  const int x0 = static_cast<int>(std::floor(x)), y0 = static_cast<int>(std::floor(y));
  const float fx = x - x0, fy = y - y0;
  // The texture repeats. The corners sit one texel outside it at most, so
  // one step wraps them; anything else (a non-finite coordinate) takes the
  // general remainder.
  auto wrap = [](int i, int n) {
    if (i < 0) i += n;
    else if (i >= n) i -= n;
    return (i >= 0 && i < n) ? i : ((i % n) + n) % n;
  };
  const int xa = wrap(x0, w), xb = wrap(x0 + 1, w);
  const cv::Vec3f* row_a = image.ptr<cv::Vec3f>(wrap(y0, h));
  const cv::Vec3f* row_b = image.ptr<cv::Vec3f>(wrap(y0 + 1, h));
  auto at = [](const cv::Vec3f* row, int xx) { return Eigen::Vector3f(row[xx][0], row[xx][1], row[xx][2]); };
  return (1 - fy) * ((1 - fx) * at(row_a, xa) + fx * at(row_a, xb)) +
         fy * ((1 - fx) * at(row_b, xa) + fx * at(row_b, xb));
}

Mesh MakeQuad(const Eigen::Vector3f& origin, const Eigen::Vector3f& du, const Eigen::Vector3f& dv,
              const Material& material) {
  Mesh m;
  m.vertices.resize(3, 4);
  m.vertices << origin, origin + du, origin + du + dv, origin + dv;
  m.triangles.resize(3, 2);
  m.triangles << 0, 0, 1, 2, 2, 3;
  m.uvs.resize(2, 4);
  m.uvs << 0, 1, 1, 0, 0, 0, 1, 1;
  m.materials = {material};
  return m;
}

Eigen::Vector3d ClosestBarycentric(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                   const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return {1, 0, 0};
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return {0, 1, 0};
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const double v = d1 / (d1 - d3);
    return {1 - v, v, 0};
  }
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return {0, 0, 1};
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const double w = d2 / (d2 - d6);
    return {1 - w, 0, w};
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return {0, 1 - w, w};
  }
  const double denom = 1.0 / (va + vb + vc);
  const double v = vb * denom, w = vc * denom;
  return {1 - v - w, v, w};
}

std::vector<TexelHit> RasteriseTexels(const Eigen::Matrix2Xf& texel_coords, const Eigen::Matrix3Xi& uv_triangles,
                                      const std::vector<int>& triangles, cv::Size size) {
  std::vector<TexelHit> hits(static_cast<size_t>(size.area()));
  for (int t : triangles) {
    Eigen::Vector2f c[3];
    for (int k = 0; k < 3; ++k) c[k] = texel_coords.col(uv_triangles(k, t));
    const float area = (c[1] - c[0]).x() * (c[2] - c[0]).y() - (c[2] - c[0]).x() * (c[1] - c[0]).y();
    if (std::abs(area) < 1e-12f) continue;
    const int x0 = std::max(0, static_cast<int>(std::floor(std::min({c[0].x(), c[1].x(), c[2].x()}))));
    const int x1 = std::min(size.width - 1, static_cast<int>(std::ceil(std::max({c[0].x(), c[1].x(), c[2].x()}))));
    const int y0 = std::max(0, static_cast<int>(std::floor(std::min({c[0].y(), c[1].y(), c[2].y()}))));
    const int y1 = std::min(size.height - 1, static_cast<int>(std::ceil(std::max({c[0].y(), c[1].y(), c[2].y()}))));
    for (int y = y0; y <= y1; ++y) {
      for (int x = x0; x <= x1; ++x) {
        const Eigen::Vector2f p(static_cast<float>(x), static_cast<float>(y));
        const float l1 = ((p - c[0]).x() * (c[2] - c[0]).y() - (c[2] - c[0]).x() * (p - c[0]).y()) / area;
        const float l2 = ((c[1] - c[0]).x() * (p - c[0]).y() - (p - c[0]).x() * (c[1] - c[0]).y()) / area;
        const float l0 = 1 - l1 - l2;
        constexpr float kEps = -0.02f;  // a little overlap closes seams between triangles
        if (l0 < kEps || l1 < kEps || l2 < kEps) continue;
        hits[static_cast<size_t>(y) * size.width + x] = TexelHit{t, Eigen::Vector3f(l0, l1, l2)};
      }
    }
  }
  return hits;
}

void PadSeams(cv::Mat* image, cv::Mat* filled, int iterations) {
  for (int i = 0; i < iterations; ++i) {
    cv::Mat grown, grown_mask;
    cv::dilate(*image, grown, cv::Mat());
    cv::dilate(*filled, grown_mask, cv::Mat());
    grown.copyTo(*image, ~*filled & grown_mask);
    *filled = grown_mask;
  }
}

Eigen::Matrix3Xf VertexNormals(const Eigen::Matrix3Xf& vertices, const Eigen::Matrix3Xi& triangles) {
  Eigen::Matrix3Xf normals = Eigen::Matrix3Xf::Zero(3, vertices.cols());
  for (int t = 0; t < triangles.cols(); ++t) {
    const Eigen::Vector3f a = vertices.col(triangles(0, t)), b = vertices.col(triangles(1, t)),
                          c = vertices.col(triangles(2, t));
    const Eigen::Vector3f n = (b - a).cross(c - a);  // length = twice the area
    for (int k = 0; k < 3; ++k) normals.col(triangles(k, t)) += n;
  }
  for (int v = 0; v < normals.cols(); ++v) {
    const float len = normals.col(v).norm();
    if (len > 0) normals.col(v) /= len;
  }
  return normals;
}

namespace {

// A triangle after near-plane clipping, in supersampled pixel coordinates.
struct ScreenTriangle {
  float x[3], y[3];
  float inv_z[3];
  // Barycentric weights of each clipped corner w.r.t. the original triangle.
  Eigen::Matrix3f original;  // column k = weights of corner k
  int mesh, triangle;
  int min_x, max_x, min_y, max_y;
  float inv_area;
};

struct ClipVertex {
  Eigen::Vector3f p;  // camera frame
  Eigen::Vector3f w;  // weights on the original corners
};

void SetUpTriangles(const std::vector<const Mesh*>& meshes, const PinholeCamera& camera, int s,
                    int ss_width, int ss_height, float near, std::vector<ScreenTriangle>* out) {
  const Eigen::Matrix3f r = camera.cam_from_world.linear().cast<float>();
  const Eigen::Vector3f t = camera.cam_from_world.translation().cast<float>();
  const float fx = static_cast<float>(camera.fx * s), fy = static_cast<float>(camera.fy * s);
  // Supersampled coordinate X = (x + 0.5) s - 0.5 keeps sample centres at integers.
  const float cx = static_cast<float>((camera.cx + 0.5) * s - 0.5);
  const float cy = static_cast<float>((camera.cy + 0.5) * s - 0.5);
  for (size_t m = 0; m < meshes.size(); ++m) {
    const Mesh& mesh = *meshes[m];
    const Eigen::Matrix3Xf cam = (r * mesh.vertices).colwise() + t;
    for (int tri = 0; tri < mesh.triangles.cols(); ++tri) {
      if (!mesh.material.empty() && mesh.material[tri] < 0) continue;
      std::array<ClipVertex, 3> corners;
      int behind = 0;
      for (int k = 0; k < 3; ++k) {
        corners[k].p = cam.col(mesh.triangles(k, tri));
        corners[k].w = Eigen::Vector3f::Unit(k);
        behind += corners[k].p.z() < near;
      }
      if (behind == 3) continue;
      // Sutherland-Hodgman against z = near (a triangle becomes at most a quad).
      std::vector<ClipVertex> poly;
      if (behind == 0) {
        poly.assign(corners.begin(), corners.end());
      } else {
        for (int k = 0; k < 3; ++k) {
          const ClipVertex& a = corners[k];
          const ClipVertex& b = corners[(k + 1) % 3];
          const bool a_in = a.p.z() >= near, b_in = b.p.z() >= near;
          if (a_in) poly.push_back(a);
          if (a_in != b_in) {
            const float f = (near - a.p.z()) / (b.p.z() - a.p.z());
            poly.push_back({a.p + f * (b.p - a.p), a.w + f * (b.w - a.w)});
          }
        }
      }
      for (size_t k = 1; k + 1 < poly.size(); ++k) {
        const ClipVertex* v[3] = {&poly[0], &poly[k], &poly[k + 1]};
        ScreenTriangle st;
        for (int c = 0; c < 3; ++c) {
          st.inv_z[c] = 1.0f / v[c]->p.z();
          st.x[c] = fx * v[c]->p.x() * st.inv_z[c] + cx;
          st.y[c] = fy * v[c]->p.y() * st.inv_z[c] + cy;
          st.original.col(c) = v[c]->w;
        }
        const float area = (st.x[1] - st.x[0]) * (st.y[2] - st.y[0]) - (st.x[2] - st.x[0]) * (st.y[1] - st.y[0]);
        if (std::abs(area) < 1e-12f || !std::isfinite(area)) continue;
        st.inv_area = 1.0f / area;
        const float x0 = std::min({st.x[0], st.x[1], st.x[2]}), x1 = std::max({st.x[0], st.x[1], st.x[2]});
        const float y0 = std::min({st.y[0], st.y[1], st.y[2]}), y1 = std::max({st.y[0], st.y[1], st.y[2]});
        if (x1 < 0 || y1 < 0 || x0 > ss_width - 1 || y0 > ss_height - 1) continue;
        st.min_x = std::max(0, static_cast<int>(std::ceil(x0)));
        st.max_x = std::min(ss_width - 1, static_cast<int>(std::floor(x1)));
        st.min_y = std::max(0, static_cast<int>(std::ceil(y0)));
        st.max_y = std::min(ss_height - 1, static_cast<int>(std::floor(y1)));
        if (st.min_x > st.max_x || st.min_y > st.max_y) continue;
        st.mesh = static_cast<int>(m);
        st.triangle = tri;
        out->push_back(st);
      }
    }
  }
}

// Visibility buffer: nearest triangle and its screen barycentrics per sample.
struct Visibility {
  std::vector<float> depth;
  std::vector<int> id;
  std::vector<float> l1, l2;
};

void Rasterise(const std::vector<ScreenTriangle>& tris, int width, int height, int threads,
               Visibility* vis) {
  const size_t n = static_cast<size_t>(width) * height;
  vis->depth.assign(n, std::numeric_limits<float>::infinity());
  vis->id.assign(n, -1);
  vis->l1.assign(n, 0.0f);
  vis->l2.assign(n, 0.0f);
  constexpr int kBand = 16;
  const int bands = (height + kBand - 1) / kBand;
  std::vector<std::vector<int>> binned(bands);
  for (size_t i = 0; i < tris.size(); ++i)
    for (int b = tris[i].min_y / kBand; b <= tris[i].max_y / kBand; ++b) binned[b].push_back(static_cast<int>(i));

  ParallelFor(bands, threads, [&](int band, int) {
    const int row0 = band * kBand, row1 = std::min(height, row0 + kBand) - 1;
    for (int index : binned[band]) {
      const ScreenTriangle& t = tris[index];
      const int y_start = std::max(row0, t.min_y), y_end = std::min(row1, t.max_y);
      for (int y = y_start; y <= y_end; ++y) {
        const float py = static_cast<float>(y);
        for (int x = t.min_x; x <= t.max_x; ++x) {
          const float px = static_cast<float>(x);
          // Signed areas opposite each corner, normalised: barycentrics.
          const float l1 = ((px - t.x[0]) * (t.y[2] - t.y[0]) - (t.x[2] - t.x[0]) * (py - t.y[0])) * t.inv_area;
          const float l2 = ((t.x[1] - t.x[0]) * (py - t.y[0]) - (px - t.x[0]) * (t.y[1] - t.y[0])) * t.inv_area;
          const float l0 = 1.0f - l1 - l2;
          if (l0 < 0.0f || l1 < 0.0f || l2 < 0.0f) continue;
          const float inv_z = l0 * t.inv_z[0] + l1 * t.inv_z[1] + l2 * t.inv_z[2];
          const float z = 1.0f / inv_z;
          const size_t at = static_cast<size_t>(y) * width + x;
          if (z >= vis->depth[at]) continue;
          vis->depth[at] = z;
          vis->id[at] = index;
          vis->l1[at] = l1;
          vis->l2[at] = l2;
        }
      }
    }
  });
}

struct Sample {
  bool hit = false;
  Eigen::Vector3f colour;
  float depth = 0.0f;
  Eigen::Vector2f uv = Eigen::Vector2f::Zero();
  Eigen::Vector3f normal = Eigen::Vector3f::Zero();
  uint8_t part = kPartBackground;
  int id = -1;
};

Sample Shade(const std::vector<const Mesh*>& meshes, const std::vector<ScreenTriangle>& tris,
             const Visibility& vis, size_t at, const RenderOptions& options) {
  Sample s;
  s.colour = options.background;
  const int index = vis.id[at];
  if (index < 0) return s;
  const ScreenTriangle& t = tris[index];
  const Mesh& mesh = *meshes[t.mesh];
  const float l1 = vis.l1[at], l2 = vis.l2[at], l0 = 1.0f - l1 - l2;
  // Perspective-correct weights on the clipped corners, then on the original ones.
  const float a0 = l0 * t.inv_z[0], a1 = l1 * t.inv_z[1], a2 = l2 * t.inv_z[2];
  const float norm = 1.0f / (a0 + a1 + a2);
  const Eigen::Vector3f b = t.original * (Eigen::Vector3f(a0, a1, a2) * norm);
  s.hit = true;
  s.depth = vis.depth[at];
  s.id = (t.mesh << 24) | t.triangle;
  const int tri = t.triangle;
  const Material& material = mesh.materials[mesh.material.empty() ? 0 : mesh.material[tri]];
  if (mesh.uvs.cols() > 0) {
    const bool own = mesh.uv_triangles.cols() > 0;
    for (int k = 0; k < 3; ++k)
      s.uv += b[k] * mesh.uvs.col(own ? mesh.uv_triangles(k, tri) : mesh.triangles(k, tri));
  }
  if (mesh.normals.cols() > 0) {
    for (int k = 0; k < 3; ++k) s.normal += b[k] * mesh.normals.col(mesh.triangles(k, tri));
  } else {
    const Eigen::Vector3f p0 = mesh.vertices.col(mesh.triangles(0, tri));
    s.normal = (mesh.vertices.col(mesh.triangles(1, tri)) - p0).cross(mesh.vertices.col(mesh.triangles(2, tri)) - p0);
  }
  const float len = s.normal.norm();
  if (len > 0) s.normal /= len;
  s.part = material.part;
  if (material.texture) {
    const float u = (s.uv.x() - material.u_offset) * material.u_scale;
    const float v = s.uv.y() * material.v_scale;
    s.colour = material.texture->Sample(u, v);
    if (material.part_map) {
      const cv::Mat& pm = *material.part_map;
      const int px = std::clamp(static_cast<int>((u - std::floor(u)) * pm.cols), 0, pm.cols - 1);
      const int py = std::clamp(static_cast<int>((1.0f - (v - std::floor(v))) * pm.rows), 0, pm.rows - 1);
      s.part = pm.at<uint8_t>(py, px);
    }
  } else {
    s.colour = material.colour;
  }
  if (options.lighting.enabled && material.lit) {
    const float diffuse = std::max(0.0f, s.normal.dot(options.lighting.direction));
    s.colour *= options.lighting.ambient + options.lighting.diffuse * diffuse;
  }
  return s;
}

}  // namespace

void RenderMeshes(const std::vector<const Mesh*>& meshes, const PinholeCamera& camera,
                  const RenderOptions& options, RenderOutput* out) {
  HF_CHECK(options.supersample >= 1);
  for (const Mesh* m : meshes) HF_CHECK(!m->materials.empty());
  const int s = options.supersample;
  const int threads = options.threads > 0 ? options.threads : DefaultThreads();
  const int w = camera.width, h = camera.height, sw = w * s, sh = h * s;
  std::vector<ScreenTriangle> tris;
  SetUpTriangles(meshes, camera, s, sw, sh, options.near, &tris);
  Visibility vis;
  Rasterise(tris, sw, sh, threads, &vis);

  out->color.create(h, w, CV_32FC3);
  out->depth.create(h, w, CV_32F);
  out->uv.create(h, w, CV_32FC2);
  out->normal.create(h, w, CV_32FC3);
  out->part.create(h, w, CV_8U);
  out->triangle.create(h, w, CV_32S);
  out->coverage.create(h, w, CV_32F);
  const int centre = s / 2;
  const float inv_samples = 1.0f / (s * s);
  ParallelFor(h, threads, [&](int y, int) {
    for (int x = 0; x < w; ++x) {
      Eigen::Vector3f sum = Eigen::Vector3f::Zero();
      int subject = 0;
      for (int sy = 0; sy < s; ++sy) {
        for (int sx = 0; sx < s; ++sx) {
          const size_t at = static_cast<size_t>(y * s + sy) * sw + (x * s + sx);
          const Sample sample = Shade(meshes, tris, vis, at, options);
          sum += sample.colour;
          subject += sample.part == kPartFace || sample.part == kPartHair;
          if (sx == centre && sy == centre) {
            out->depth.at<float>(y, x) = sample.hit ? sample.depth : 0.0f;
            out->uv.at<cv::Vec2f>(y, x) = cv::Vec2f(sample.uv.x(), sample.uv.y());
            out->normal.at<cv::Vec3f>(y, x) = cv::Vec3f(sample.normal.x(), sample.normal.y(), sample.normal.z());
            out->part.at<uint8_t>(y, x) = sample.part;
            out->triangle.at<int>(y, x) = sample.id;
          }
        }
      }
      sum *= inv_samples;
      out->color.at<cv::Vec3f>(y, x) = cv::Vec3f(sum.x(), sum.y(), sum.z());
      out->coverage.at<float>(y, x) = subject * inv_samples;
    }
  });
}

}  // namespace headforge
