#include "capture/simulator.h"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <random>

#include "capture/procedural.h"
#include "core/log.h"

namespace headforge {
namespace {

constexpr double kPi = 3.14159265358979323846;
double Radians(double degrees) { return degrees * kPi / 180.0; }

Mesh Quad(const Eigen::Vector3f& origin, const Eigen::Vector3f& du, const Eigen::Vector3f& dv,
          const Texture* texture, float repeat) {
  Material material;
  material.texture = texture;
  material.u_scale = material.v_scale = repeat;
  material.part = kPartBackground;
  return MakeQuad(origin, du, dv, material);
}

Mesh Sphere(float radius, const Texture* texture) {
  constexpr int kRings = 16, kSegments = 24;
  Mesh m;
  m.vertices.resize(3, (kRings + 1) * (kSegments + 1));
  m.uvs.resize(2, m.vertices.cols());
  for (int r = 0; r <= kRings; ++r) {
    for (int s = 0; s <= kSegments; ++s) {
      const double theta = kPi * r / kRings, phi = 2 * kPi * s / kSegments;
      const int i = r * (kSegments + 1) + s;
      m.vertices.col(i) = radius * Eigen::Vector3f(static_cast<float>(std::sin(theta) * std::cos(phi)),
                                                   static_cast<float>(std::cos(theta)),
                                                   static_cast<float>(std::sin(theta) * std::sin(phi)));
      m.uvs.col(i) = Eigen::Vector2f(static_cast<float>(s) / kSegments, 1.0f - static_cast<float>(r) / kRings);
    }
  }
  m.triangles.resize(3, 2 * kRings * kSegments);
  int t = 0;
  for (int r = 0; r < kRings; ++r)
    for (int s = 0; s < kSegments; ++s) {
      const int a = r * (kSegments + 1) + s, b = a + kSegments + 1;
      m.triangles.col(t++) = Eigen::Vector3i(a, b, a + 1);
      m.triangles.col(t++) = Eigen::Vector3i(a + 1, b, b + 1);
    }
  Material material;
  material.texture = texture;
  material.part = kPartOccluder;
  m.materials = {material};
  return m;
}

Eigen::Vector3f Bgr(const Eigen::Vector3f& rgb) { return Eigen::Vector3f(rgb.z(), rgb.y(), rgb.x()); }

// Normalised image point after radial distortion.
Eigen::Vector2d Distort(const Eigen::Vector2d& x, double k1, double k2) {
  const double r2 = x.squaredNorm();
  return x * (1.0 + k1 * r2 + k2 * r2 * r2);
}

Eigen::Vector2d Undistort(const Eigen::Vector2d& xd, double k1, double k2) {
  Eigen::Vector2d x = xd;
  for (int i = 0; i < 20; ++i) {
    const double r2 = x.squaredNorm();
    x = xd / (1.0 + k1 * r2 + k2 * r2 * r2);
  }
  return x;
}

uint64_t ViewSeed(int scene_seed, int frame, int camera, uint64_t salt) {
  return Hash64(Hash64(Hash64(static_cast<uint64_t>(scene_seed) ^ salt) + static_cast<uint64_t>(frame)) +
                static_cast<uint64_t>(camera));
}

}  // namespace

Status Simulator::Create(const Scene& scene, const FaceModel& model, int threads,
                         std::unique_ptr<Simulator>* simulator) {
  HF_RETURN_IF_ERROR(scene.Check());
  if (!model.has_uv() || model.landmarks_ibug68().size() != 68)
    return Status::InvalidArgument("the simulator needs a face model with UVs and iBUG-68 landmarks (the ICT model)");
  std::unique_ptr<Simulator> s(new Simulator(scene, model));
  s->threads_ = std::max(1, threads);
  // Identity.
  if (scene.random_identity) {
    const int modes = std::min(scene.identity_modes, model.num_identity());
    s->identity_ = Eigen::VectorXf::Zero(modes);
    std::mt19937_64 rng(static_cast<uint64_t>(scene.identity_seed));
    std::normal_distribution<double> normal(0.0, scene.identity_scale);
    for (int i = 0; i < modes; ++i) s->identity_[i] = static_cast<float>(normal(rng));
  } else {
    if (static_cast<int>(scene.identity.size()) > model.num_identity())
      return Status::InvalidArgument("subject.identity has more coefficients than the model's " +
                                     std::to_string(model.num_identity()));
    s->identity_ = Eigen::Map<const Eigen::VectorXd>(scene.identity.data(), scene.identity.size()).cast<float>();
  }
  s->identity_shape_ = model.Identity(s->identity_);
  for (const auto& [name, curve] : s->scene_.expressions) {  // the copy: pointers must outlive `scene`
    const int index = model.ExpressionIndex(name);
    if (index < 0) return Status::InvalidArgument("expressions." + name + ": the face model has no such blendshape");
    s->expression_index_.push_back(index);
    s->expression_curve_.push_back(&curve);
  }
  s->appearance_ = MakeHeadAppearance(model, s->identity_shape_, scene);
  s->head_template_ = MakeHeadMesh(model, s->appearance_);

  const uint64_t bg_seed = Hash64(static_cast<uint64_t>(scene.background_seed));
  if (scene.background == "backdrop") {
    s->background_texture_[0] = MakePatternTexture(2048, bg_seed, scene.background_colour);
    const float d = static_cast<float>(scene.backdrop_distance), w = 3.0f;
    s->background_.push_back(Quad({-w / 2, -w / 2, -d}, {w, 0, 0}, {0, w, 0}, &s->background_texture_[0], 1.0f));
  } else if (scene.background == "room") {
    const float h = static_cast<float>(scene.room_size) / 2;
    const Eigen::Vector3f corners[6][3] = {
        {{-h, -h, -h}, {2 * h, 0, 0}, {0, 2 * h, 0}},  {{h, -h, h}, {-2 * h, 0, 0}, {0, 2 * h, 0}},
        {{-h, -h, h}, {0, 0, -2 * h}, {0, 2 * h, 0}},  {{h, -h, -h}, {0, 0, 2 * h}, {0, 2 * h, 0}},
        {{-h, -h, h}, {2 * h, 0, 0}, {0, 0, -2 * h}},  {{-h, h, -h}, {2 * h, 0, 0}, {0, 0, 2 * h}}};
    for (int i = 0; i < 6; ++i) {
      const Eigen::Vector3f tint = scene.background_colour.cwiseProduct(
          Eigen::Vector3f(0.8f + 0.08f * i, 1.1f - 0.07f * i, 0.9f + 0.03f * i)).cwiseMin(1.0f);
      s->background_texture_[i] = MakePatternTexture(2048, bg_seed + i, tint);
      s->background_.push_back(Quad(corners[i][0], corners[i][1], corners[i][2], &s->background_texture_[i], 1.0f));
    }
  }
  if (scene.HasEffect("occlusion")) {
    s->occluder_texture_ = MakePatternTexture(256, bg_seed + 99, Eigen::Vector3f(0.8f, 0.6f, 0.3f));
    s->occluder_template_ = Sphere(static_cast<float>(scene.Param("occlusion", "radius", 0.035)), &s->occluder_texture_);
  }
  *simulator = std::move(s);
  return Status::Ok();
}

int Simulator::num_cameras() const {
  if (scene_.camera.rig != "rig") return 1;
  return scene_.camera.positions.empty() ? scene_.camera.count : static_cast<int>(scene_.camera.positions.size());
}

SubjectState Simulator::StateAt(double t) const {
  SubjectState state;
  const Eigen::Matrix3d r = (Eigen::AngleAxisd(Radians(scene_.yaw.Evaluate(t)), Eigen::Vector3d::UnitY()) *
                             Eigen::AngleAxisd(Radians(scene_.pitch.Evaluate(t)), Eigen::Vector3d::UnitX()) *
                             Eigen::AngleAxisd(Radians(scene_.roll.Evaluate(t)), Eigen::Vector3d::UnitZ()))
                                .toRotationMatrix();
  state.world_from_head.linear() = r;
  state.world_from_head.translation() =
      Eigen::Vector3d(scene_.tx.Evaluate(t), scene_.ty.Evaluate(t), scene_.tz.Evaluate(t));
  state.expression = Eigen::VectorXf::Zero(model_.num_expressions());
  for (size_t i = 0; i < expression_index_.size(); ++i)
    state.expression[expression_index_[i]] =
        static_cast<float>(std::clamp(expression_curve_[i]->Evaluate(t), 0.0, 1.0));
  return state;
}

PinholeCamera Simulator::CameraAt(int camera, double t) const {
  const SceneCamera& c = scene_.camera;
  PinholeCamera cam;
  cam.width = c.intrinsics.width;
  cam.height = c.intrinsics.height;
  cam.fx = cam.fy = c.intrinsics.fx();
  cam.cx = c.intrinsics.cx_or_centre();
  cam.cy = c.intrinsics.cy_or_centre();
  auto on_sphere = [&](double azimuth_deg, double elevation_deg) {
    const double az = Radians(azimuth_deg), el = Radians(elevation_deg);
    return Eigen::Vector3d(c.target + c.radius * Eigen::Vector3d(std::sin(az) * std::cos(el), std::sin(el),
                                                                 std::cos(az) * std::cos(el)));
  };
  if (c.rig == "static") {
    cam.cam_from_world = LookAt(c.position, c.target);
  } else if (c.rig == "orbit") {
    const int rings = static_cast<int>(c.elevations.size());
    const double per_ring = std::ceil(static_cast<double>(num_frames()) / rings);
    const double s = t * scene_.fps;
    const int ring = std::min(rings - 1, static_cast<int>(std::floor(s / per_ring)));
    cam.cam_from_world = LookAt(on_sphere(360.0 * (s - ring * per_ring) / per_ring, c.elevations[ring]), c.target);
  } else if (c.rig == "rig") {
    Eigen::Vector3d eye;
    if (!c.positions.empty()) {
      eye = c.positions[camera];
    } else {
      const double az = c.count > 1 ? -c.arc_deg / 2 + c.arc_deg * camera / (c.count - 1) : 0.0;
      eye = on_sphere(az, c.elevation_deg);
    }
    cam.cam_from_world = LookAt(eye, c.target);
  } else {  // handheld
    const uint64_t seed = Hash64(static_cast<uint64_t>(scene_.seed) + 77);
    const double u = t / c.shake_timescale;
    const Eigen::Vector3d shake(ValueNoise1(u, seed), ValueNoise1(u, seed + 1), ValueNoise1(u, seed + 2));
    const Eigen::Vector3d eye = c.position + c.shake_m * shake;
    const double reach = (c.target - eye).norm() * std::tan(Radians(c.shake_deg));
    const Eigen::Vector3d aim(ValueNoise1(u, seed + 3), ValueNoise1(u, seed + 4), 0.0);
    cam.cam_from_world = LookAt(eye, c.target + reach * aim);
  }
  return cam;
}

Eigen::Matrix3Xf Simulator::WorldVertices(const SubjectState& state) const {
  Eigen::Matrix3Xf v = identity_shape_;
  model_.AddExpression(state.expression, &v);
  const Eigen::Matrix3f r = state.world_from_head.linear().cast<float>();
  const Eigen::Vector3f t = state.world_from_head.translation().cast<float>();
  return (r * v).colwise() + t;
}

RenderOutput Simulator::RenderOnce(int camera, double t, const PinholeCamera& canvas) const {
  const SubjectState state = StateAt(t);
  Mesh head = head_template_;
  head.vertices = WorldVertices(state);
  head.normals = VertexNormals(head.vertices, head.triangles);
  PinholeCamera cam = canvas;
  cam.cam_from_world = CameraAt(camera, t).cam_from_world;
  std::vector<const Mesh*> meshes = {&head};
  for (const auto& m : background_) meshes.push_back(&m);
  Mesh occluder;
  if (scene_.HasEffect("occlusion")) {
    const double duration = num_frames() / scene_.fps;
    const double t0 = scene_.Param("occlusion", "t_start", 0.2 * duration);
    const double t1 = scene_.Param("occlusion", "t_end", 0.8 * duration);
    if (t >= t0 && t <= t1) {
      const double f = t1 > t0 ? (t - t0) / (t1 - t0) : 0.5;
      const Eigen::Vector3d a(scene_.Param("occlusion", "x0", -0.15), scene_.Param("occlusion", "y0", -0.02),
                              scene_.Param("occlusion", "z0", 0.22));
      const Eigen::Vector3d b(scene_.Param("occlusion", "x1", 0.15), scene_.Param("occlusion", "y1", -0.02),
                              scene_.Param("occlusion", "z1", 0.22));
      occluder = occluder_template_;
      occluder.vertices.colwise() += (a + f * (b - a)).cast<float>();
      meshes.push_back(&occluder);
    }
  }
  RenderOptions options;
  options.supersample = scene_.supersample;
  options.threads = threads_;
  options.background = Bgr(scene_.background_colour);
  if (scene_.HasEffect("lighting")) {
    options.lighting.enabled = true;
    options.lighting.direction = Eigen::Vector3f(static_cast<float>(scene_.Param("lighting", "x", 0.5)),
                                                 static_cast<float>(scene_.Param("lighting", "y", 0.6)),
                                                 static_cast<float>(scene_.Param("lighting", "z", 0.8)))
                                     .normalized();
    options.lighting.ambient = static_cast<float>(scene_.Param("lighting", "ambient", 0.35));
    options.lighting.diffuse = static_cast<float>(scene_.Param("lighting", "diffuse", 0.8));
  }
  RenderOutput out;
  RenderMeshes(meshes, cam, options, &out);
  return out;
}

RenderOutput Simulator::RenderAt(int camera, const std::vector<double>& band_times, const PinholeCamera& canvas) const {
  if (band_times.size() == 1) return RenderOnce(camera, band_times[0], canvas);
  RenderOutput out;
  const int bands = static_cast<int>(band_times.size());
  for (int b = 0; b < bands; ++b) {
    const RenderOutput part = RenderOnce(camera, band_times[b], canvas);
    if (b == 0) out = part;
    const int y0 = b * canvas.height / bands, y1 = (b + 1) * canvas.height / bands;
    const cv::Range rows(y0, y1);
    for (auto [dst, src] : {std::pair<cv::Mat*, const cv::Mat*>{&out.color, &part.color}, {&out.depth, &part.depth},
                            {&out.uv, &part.uv}, {&out.normal, &part.normal}, {&out.part, &part.part},
                            {&out.triangle, &part.triangle}, {&out.coverage, &part.coverage}})
      src->rowRange(rows).copyTo(dst->rowRange(rows));
  }
  return out;
}

namespace {

// The undistorted canvas of a distorted camera: `base` enlarged to hold every
// source of a distorted pixel.
PinholeCamera DistortionCanvas(const PinholeCamera& base, double k1, double k2) {
  PinholeCamera canvas = base;
  double x_min = 0, y_min = 0, x_max = base.width - 1, y_max = base.height - 1;
  for (int i = 0; i <= 64; ++i) {
    const double f = i / 64.0;
    for (const Eigen::Vector2d& d : {Eigen::Vector2d(f * (base.width - 1), 0), Eigen::Vector2d(f * (base.width - 1), base.height - 1),
                                     Eigen::Vector2d(0, f * (base.height - 1)), Eigen::Vector2d(base.width - 1, f * (base.height - 1))}) {
      const Eigen::Vector2d u = Undistort(Eigen::Vector2d((d.x() - base.cx) / base.fx, (d.y() - base.cy) / base.fy), k1, k2);
      const double px = base.fx * u.x() + base.cx, py = base.fy * u.y() + base.cy;
      x_min = std::min(x_min, px);
      x_max = std::max(x_max, px);
      y_min = std::min(y_min, py);
      y_max = std::max(y_max, py);
    }
  }
  x_min = std::floor(x_min) - 2;
  y_min = std::floor(y_min) - 2;
  canvas.width = static_cast<int>(std::ceil(x_max - x_min)) + 3;
  canvas.height = static_cast<int>(std::ceil(y_max - y_min)) + 3;
  canvas.cx = base.cx - x_min;
  canvas.cy = base.cy - y_min;
  return canvas;
}

// The canvas's colour, coverage and depth warped to the distorted image:
// for each output pixel, where its light lands on the canvas.
void WarpToDistorted(const PinholeCamera& base, const PinholeCamera& canvas, double k1, double k2, cv::Mat* colour,
                     cv::Mat* coverage, cv::Mat* depth) {
  cv::Mat map_x(base.height, base.width, CV_32F), map_y(base.height, base.width, CV_32F);
  for (int y = 0; y < base.height; ++y)
    for (int x = 0; x < base.width; ++x) {
      const Eigen::Vector2d u = Undistort(Eigen::Vector2d((x - base.cx) / base.fx, (y - base.cy) / base.fy), k1, k2);
      map_x.at<float>(y, x) = static_cast<float>(base.fx * u.x() + canvas.cx);
      map_y.at<float>(y, x) = static_cast<float>(base.fy * u.y() + canvas.cy);
    }
  cv::Mat warped, warped_coverage, warped_depth;
  cv::remap(*colour, warped, map_x, map_y, cv::INTER_LINEAR, cv::BORDER_REPLICATE);
  cv::remap(*coverage, warped_coverage, map_x, map_y, cv::INTER_LINEAR, cv::BORDER_CONSTANT);
  cv::remap(*depth, warped_depth, map_x, map_y, cv::INTER_NEAREST, cv::BORDER_CONSTANT);
  *colour = warped;
  *coverage = warped_coverage;
  *depth = warped_depth;
}

// Defocus: the circle of confusion grows with |z - focus| / z; blends
// between blur levels.
cv::Mat DefocusBlur(const cv::Mat& colour, const cv::Mat& depth, double focus, double strength) {
  const std::vector<double> radii = {0, 1, 2, 4, 8, 16};
  std::vector<cv::Mat> levels;
  for (double r : radii) {
    cv::Mat l;
    if (r == 0) l = colour;
    else cv::GaussianBlur(colour, l, cv::Size(0, 0), r / 2.0);
    levels.push_back(l);
  }
  cv::Mat out = colour.clone();
  for (int y = 0; y < colour.rows; ++y)
    for (int x = 0; x < colour.cols; ++x) {
      const float z = depth.at<float>(y, x);
      const double coc = std::min(radii.back(), strength * std::abs((z > 0 ? z : 100.0) - focus) / (z > 0 ? z : 100.0));
      size_t k = 0;
      while (k + 2 < radii.size() && radii[k + 1] < coc) ++k;
      const float f = static_cast<float>(std::clamp((coc - radii[k]) / (radii[k + 1] - radii[k]), 0.0, 1.0));
      out.at<cv::Vec3f>(y, x) = (1 - f) * levels[k].at<cv::Vec3f>(y, x) + f * levels[k + 1].at<cv::Vec3f>(y, x);
    }
  return out;
}

}  // namespace

std::vector<double> Simulator::BandOffsets() const {
  if (!scene_.HasEffect("rolling_shutter")) return {0.0};
  const double frame_interval = 1.0 / scene_.fps;
  const double readout = scene_.Param("rolling_shutter", "readout", 0.6) * frame_interval;
  const int bands = std::max(2, static_cast<int>(scene_.Param("rolling_shutter", "bands", 8)));
  std::vector<double> offsets(size_t(bands), 0.0);
  for (int b = 0; b < bands; ++b) offsets[size_t(b)] = ((b + 0.5) / bands - 0.5) * readout;
  return offsets;
}

cv::Mat Simulator::Expose(int camera, double t, const PinholeCamera& canvas, RenderOutput* middle) const {
  // Row bands (rolling shutter) and sub-frame samples (motion blur).
  const std::vector<double> band_offsets = BandOffsets();
  const bool blur = scene_.HasEffect("motion_blur");
  const int samples = blur ? std::max(2, static_cast<int>(scene_.Param("motion_blur", "samples", 5))) : 1;
  const double frame_interval = 1.0 / scene_.fps;
  const double shutter = scene_.Param("motion_blur", "shutter", 0.5) * frame_interval;
  cv::Mat colour;
  for (int i = 0; i < samples; ++i) {
    const double dt = blur ? ((i + 0.5) / samples - 0.5) * shutter : 0.0;
    std::vector<double> times;
    for (double o : band_offsets) times.push_back(t + dt + o);
    RenderOutput r = RenderAt(camera, times, canvas);
    if (i == 0) colour = r.color.clone();
    else colour += r.color;
    if (i == samples / 2) *middle = std::move(r);
  }
  if (samples > 1) colour /= samples;
  return colour;
}

void Simulator::ApplySensorEffects(int frame, int camera, double t, cv::Mat* colour) const {
  if (scene_.HasEffect("exposure_drift")) {
    const double ev = scene_.Param("exposure_drift", "amplitude", 0.3);
    const double timescale = scene_.Param("exposure_drift", "timescale", 1.0);
    const uint64_t seed = Hash64(static_cast<uint64_t>(scene_.seed) * 31 + camera + 1000);
    *colour *= std::pow(2.0, ev * ValueNoise1(t / timescale, seed));
  }
  if (scene_.HasEffect("white_balance_drift")) {
    const double amplitude = scene_.Param("white_balance_drift", "amplitude", 0.06);
    const double timescale = scene_.Param("white_balance_drift", "timescale", 1.5);
    const uint64_t seed = Hash64(static_cast<uint64_t>(scene_.seed) * 37 + camera + 2000);
    const cv::Scalar gains(std::exp(amplitude * ValueNoise1(t / timescale, seed)), 1.0,
                           std::exp(amplitude * ValueNoise1(t / timescale, seed + 1)));
    cv::multiply(*colour, gains, *colour);
  }
  if (scene_.HasEffect("sensor_noise")) {
    const double read = scene_.Param("sensor_noise", "sigma", 2.0) / 255.0;
    const double shot = scene_.Param("sensor_noise", "shot", 0.01);
    cv::RNG rng(ViewSeed(scene_.seed, frame, camera, 0x5e5));
    for (int y = 0; y < colour->rows; ++y)
      for (int x = 0; x < colour->cols; ++x) {
        cv::Vec3f& p = colour->at<cv::Vec3f>(y, x);
        for (int c = 0; c < 3; ++c)
          p[c] += static_cast<float>(rng.gaussian(std::sqrt(read * read + shot * std::max(0.0f, p[c]) / 255.0)));
      }
  }
}

void Simulator::PlaceLandmarks(int camera, double t, const PinholeCamera& canvas, SimulatedView* view) const {
  const PinholeCamera& base = view->camera;
  const bool rolling = scene_.HasEffect("rolling_shutter");
  const bool distort = scene_.HasEffect("lens_distortion");
  const std::vector<double> band_offsets = BandOffsets();
  const int bands = static_cast<int>(band_offsets.size());
  const auto& lm = model_.landmarks_ibug68();
  view->landmarks.resize(68);
  view->visible.resize(68);
  view->depth.resize(68);
  const Eigen::Matrix3Xf frame_vertices = WorldVertices(StateAt(t));
  for (int i = 0; i < 68; ++i) {
    Eigen::Vector3d p = frame_vertices.col(lm[i]).cast<double>();
    PinholeCamera cam = base;
    if (rolling) {
      // At the time the landmark's row was exposed.
      double tl = t;
      for (int iter = 0; iter < 3; ++iter) {
        const double row = cam.Project(p).y() + (canvas.cy - base.cy);
        const int band = std::clamp(static_cast<int>(row / canvas.height * bands), 0, bands - 1);
        tl = t + band_offsets[size_t(band)];
        p = WorldVertices(StateAt(tl)).col(lm[i]).cast<double>();
        cam.cam_from_world = CameraAt(camera, tl).cam_from_world;
      }
    }
    double z = 0;
    Eigen::Vector2d px = cam.Project(p, &z);
    view->depth[i] = z;
    // Visible when nothing nearer covers it in the (undistorted) render.
    const int cx = static_cast<int>(std::lround(px.x() + (canvas.cx - base.cx)));
    const int cy = static_cast<int>(std::lround(px.y() + (canvas.cy - base.cy)));
    bool visible = z > 0 && cx >= 0 && cy >= 0 && cx < canvas.width && cy < canvas.height;
    if (visible) {
      const float rendered = view->render.depth.at<float>(cy, cx);
      visible = rendered > 0 && rendered > z - 0.008;
    }
    if (distort) {
      const Eigen::Vector2d d = Distort(Eigen::Vector2d((px.x() - base.cx) / base.fx, (px.y() - base.cy) / base.fy), view->k1, view->k2);
      px = Eigen::Vector2d(base.fx * d.x() + base.cx, base.fy * d.y() + base.cy);
    }
    visible = visible && px.x() >= -0.5 && px.y() >= -0.5 && px.x() < base.width - 0.5 && px.y() < base.height - 0.5;
    view->landmarks[i] = px;
    view->visible[i] = visible;
  }
}

SimulatedView Simulator::RenderView(int frame, int camera) const {
  const double t = FrameTime(frame);
  SimulatedView view;
  view.camera = CameraAt(camera, t);
  const PinholeCamera& base = view.camera;
  const bool distort = scene_.HasEffect("lens_distortion");
  if (distort) {
    const bool given = scene_.camera.intrinsics.k1 != 0.0 || scene_.camera.intrinsics.k2 != 0.0;
    view.k1 = given ? scene_.camera.intrinsics.k1 : scene_.Param("lens_distortion", "k1", -0.2);
    view.k2 = given ? scene_.camera.intrinsics.k2 : scene_.Param("lens_distortion", "k2", 0.05);
  }
  const PinholeCamera canvas = distort ? DistortionCanvas(base, view.k1, view.k2) : base;
  cv::Mat colour = Expose(camera, t, canvas, &view.render);
  cv::Mat coverage = view.render.coverage;
  cv::Mat depth = view.render.depth;
  if (distort) WarpToDistorted(base, canvas, view.k1, view.k2, &colour, &coverage, &depth);
  if (scene_.HasEffect("defocus_blur")) {
    const double focus = scene_.Param("defocus_blur", "focus", (base.Centre() - scene_.camera.target).norm());
    colour = DefocusBlur(colour, depth, focus, scene_.Param("defocus_blur", "strength", 8.0));
  }
  ApplySensorEffects(frame, camera, t, &colour);
  colour.convertTo(view.image, CV_8UC3, 255.0);
  view.mask = coverage > 0.5f;
  PlaceLandmarks(camera, t, canvas, &view);
  return view;
}

}  // namespace headforge
