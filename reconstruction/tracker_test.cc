// Tracking on synthetic landmark sequences made from the face model itself:
// recovered expressions, head motion and landmark positions against the
// truth, and the hard cases staying finite and flagged.
#include "reconstruction/tracker.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <random>

#include "calibration/landmark_embedding.h"
#include "calibration/mesh_embedding.h"
#include "core/paths.h"
#include "core/face_model.h"
#include "core/json_io.h"
#include "core/progress.h"
#include "reconstruction/track_stage.h"

namespace headforge {
namespace {

const FaceModel& Model() {
  static const FaceModel* model = [] {
    auto* m = new FaceModel();
    const Status s = FaceModel::Load(std::string(HEADFORGE_TEST_SHARED_DATA) + "/ict_facekit/ict_face_model.h5", m);
    if (!s.ok()) throw std::runtime_error(s.message());
    return m;
  }();
  return *model;
}

const LandmarkBasis& Basis() {
  static const LandmarkBasis* basis = [] {
    auto* b = new LandmarkBasis();
    const auto points = DetectorLandmarkPoints(Model(), DefaultLandmarkEmbedding());
    const Status s = BuildLandmarkBasis(Model(), points, 20, b);
    if (!s.ok()) throw std::runtime_error(s.message());
    return b;
  }();
  return *basis;
}

// A camera `distance` metres in front of the face, turned by `yaw_deg` about
// the head's vertical axis, OpenCV axes.
TrackingCamera CameraAt(double yaw_deg, double focal = 900, double distance = 0.6) {
  TrackingCamera c;
  c.fx = c.fy = focal;
  c.cx = 255.5;
  c.cy = 255.5;
  const Eigen::Matrix3d flip = Eigen::Vector3d(1, -1, -1).asDiagonal();  // head +y up, +z toward the camera
  const Eigen::Matrix3d head_from_cam_rot =
      Eigen::AngleAxisd(yaw_deg * M_PI / 180, Eigen::Vector3d::UnitY()).toRotationMatrix() * flip;
  const Eigen::Vector3d centre =
      Eigen::AngleAxisd(yaw_deg * M_PI / 180, Eigen::Vector3d::UnitY()) * Eigen::Vector3d(0, 0, distance);
  c.rotation = head_from_cam_rot.transpose();
  c.translation = -c.rotation * centre;
  return c;
}

struct Truth {
  Eigen::VectorXd alpha;
  std::vector<Eigen::Isometry3d> motion;
  std::vector<Eigen::VectorXd> beta;
};

const std::vector<std::string> kAnimated = {"jawOpen", "eyeBlink_L", "eyeBlink_R", "mouthSmile_L", "mouthSmile_R"};

Truth MakeTruth(int frames, double head_motion, uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> n(0.0, 1.0);
  Truth t;
  t.alpha = Eigen::VectorXd::Zero(20);
  for (int k = 0; k < 20; ++k) t.alpha[k] = 0.8 * n(rng);
  for (int f = 0; f < frames; ++f) {
    const double s = f / double(frames);
    Eigen::Isometry3d m = Eigen::Isometry3d::Identity();
    m.linear() = (Eigen::AngleAxisd(head_motion * 0.2 * std::sin(2 * M_PI * s), Eigen::Vector3d::UnitY()) *
                  Eigen::AngleAxisd(head_motion * 0.1 * std::sin(4 * M_PI * s + 1), Eigen::Vector3d::UnitX()))
                     .toRotationMatrix();
    m.translation() = head_motion * Eigen::Vector3d(0.01 * std::sin(2 * M_PI * s), 0.005 * std::cos(2 * M_PI * s), 0);
    t.motion.push_back(m);
    Eigen::VectorXd beta = Eigen::VectorXd::Zero(Basis().num_expressions);
    const auto set = [&](const std::string& name, double v) { beta[Model().ExpressionIndex(name)] = v; };
    set("jawOpen", 0.5 + 0.5 * std::sin(6 * M_PI * s));
    const double blink = std::max(0.0, std::cos(10 * M_PI * s) * 2 - 1);
    set("eyeBlink_L", blink);
    set("eyeBlink_R", blink);
    set("mouthSmile_L", 0.3 + 0.3 * std::sin(2 * M_PI * s + 0.5));
    set("mouthSmile_R", 0.3 + 0.3 * std::sin(2 * M_PI * s + 0.7));
    t.beta.push_back(beta);
  }
  return t;
}

std::vector<TrackingView> Observe(const Truth& t, const std::vector<TrackingCamera>& cameras, double noise_px,
                                  uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> n(0.0, noise_px);
  std::vector<TrackingView> views;
  for (size_t f = 0; f < t.motion.size(); ++f) {
    for (const TrackingCamera& c : cameras) {
      TrackingView v;
      v.frame = int(f);
      v.camera = c;
      std::array<Eigen::Vector2d, 68> points;
      for (int i = 0; i < 68; ++i) {
        const Eigen::Vector3d p = c.rotation * (t.motion[f] * Basis().Point(i, t.alpha, t.beta[f])) + c.translation;
        points[i] = Eigen::Vector2d(c.fx * p.x() / p.z() + c.cx + n(rng), c.fy * p.y() / p.z() + c.cy + n(rng));
      }
      v.landmarks = points;
      views.push_back(v);
    }
  }
  return views;
}

double RotationErrorDeg(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  return Eigen::AngleAxisd(a.linear().transpose() * b.linear()).angle() * 180 / M_PI;
}

struct Scores {
  double residual = 0, expression_mae = 0, rotation_deg = 0, landmark_mm = 0;
};

Scores Score(const Truth& t, const TrackResult& r) {
  Scores s;
  std::vector<double> rot;
  double mae = 0, mm = 0;
  int count = 0, points = 0;
  for (size_t f = 0; f < t.motion.size(); ++f) {
    rot.push_back(RotationErrorDeg(t.motion[f], r.frames[f].head_motion));
    for (const auto& name : kAnimated) {
      const int j = Model().ExpressionIndex(name);
      mae += std::abs(t.beta[f][j] - r.frames[f].expression[j]);
      ++count;
    }
    // Shape error: both point sets about their own centroid (one view cannot
    // tell a head's distance from its size exactly, so absolute positions may
    // slide along the view axis).
    Eigen::Matrix3Xd truth(3, 68), fit(3, 68);
    for (int i = 0; i < 68; ++i) {
      truth.col(i) = t.motion[f] * Basis().Point(i, t.alpha, t.beta[f]);
      fit.col(i) = r.frames[f].head_motion * Basis().Point(i, r.identity, r.frames[f].expression);
    }
    truth.colwise() -= truth.rowwise().mean();
    fit.colwise() -= fit.rowwise().mean();
    for (int i = 0; i < 68; ++i) {
      mm += 1000 * (truth.col(i) - fit.col(i)).norm();
      ++points;
    }
  }
  std::nth_element(rot.begin(), rot.begin() + rot.size() / 2, rot.end());
  s.rotation_deg = rot[rot.size() / 2];
  s.expression_mae = mae / count;
  s.landmark_mm = mm / points;
  s.residual = r.median_residual_px;
  return s;
}

TEST(Tracker, MonocularSequenceRecoversExpressionsAndMotion) {
  const Truth truth = MakeTruth(40, 1.0, 1);
  const auto views = Observe(truth, {CameraAt(0)}, 0.5, 2);
  TrackOptions options;
  TrackResult result;
  const Status status = TrackSequence(Basis(), views, 40, options, &result);
  ASSERT_TRUE(status.ok()) << status.message();
  const Scores s = Score(truth, result);
  std::printf("mono: residual %.2f px, expression MAE %.3f, rotation %.2f deg, landmarks %.2f mm, %d it, %.2f s\n",
              s.residual, s.expression_mae, s.rotation_deg, s.landmark_mm, result.iterations, result.seconds);
  EXPECT_LT(s.residual, 1.0);
  EXPECT_LT(s.expression_mae, 0.1);
  EXPECT_LT(s.rotation_deg, 1.5);
  EXPECT_LT(s.landmark_mm, 3.0);
  for (const auto& f : result.frames) EXPECT_FALSE(f.low_confidence) << f.frame << ": " << f.why;
}

TEST(Tracker, MultiViewFramesAreFittedJointly) {
  const Truth truth = MakeTruth(20, 1.0, 3);
  const auto views = Observe(truth, {CameraAt(-30), CameraAt(0), CameraAt(30)}, 0.5, 4);
  TrackResult result;
  ASSERT_TRUE(TrackSequence(Basis(), views, 20, TrackOptions(), &result).ok());
  EXPECT_EQ(result.dropped_views, 0);
  const Scores s = Score(truth, result);
  std::printf("3 views: residual %.2f px, expression MAE %.3f, rotation %.2f deg, landmarks %.2f mm\n", s.residual,
              s.expression_mae, s.rotation_deg, s.landmark_mm);
  EXPECT_LT(s.residual, 1.0);
  EXPECT_LT(s.expression_mae, 0.06);
  EXPECT_LT(s.rotation_deg, 0.5);
  EXPECT_LT(s.landmark_mm, 1.0);
}

const LandmarkBasis& MeshBasis() {
  static const LandmarkBasis* basis = [] {
    auto* b = new LandmarkBasis();
    std::vector<Eigen::Vector3d> points;
    Status s = ReadMeshEmbedding(DefaultMeshEmbedding(), &points);
    if (s.ok()) s = BuildLandmarkBasis(Model(), points, 20, b);
    if (!s.ok()) throw std::runtime_error(s.message());
    return b;
  }();
  return *basis;
}

// The face mesh's points enter the fit beside the 68 (mesh_weight > 0): on
// synthetic views whose 68 points carry 3 px of noise and whose mesh points
// 1 px, the mesh brings the head's rotation and the expressions closer to
// the truth; its points ride the mesh basis, so a view's mesh moved by 4 px
// shows in the fit's head motion, and at weight 0 nothing of it does.
TEST(Tracker, TheFaceMeshEntersTheFitBesideThe68Points) {
  const Truth truth = MakeTruth(20, 1.0, 5);
  std::vector<TrackingView> views = Observe(truth, {CameraAt(0)}, 3.0, 6);
  std::mt19937 rng(7);
  std::normal_distribution<double> n(0.0, 1.0);
  for (TrackingView& v : views) {
    const size_t f = size_t(v.frame);
    for (int i = 0; i < MeshBasis().size(); ++i) {
      const Eigen::Vector3d p =
          v.camera.rotation * (truth.motion[f] * MeshBasis().Point(i, truth.alpha, truth.beta[f])) + v.camera.translation;
      v.mesh.emplace_back(v.camera.fx * p.x() / p.z() + v.camera.cx + n(rng),
                          v.camera.fy * p.y() / p.z() + v.camera.cy + n(rng));
    }
  }
  TrackOptions alone;
  TrackResult without, with;
  ASSERT_TRUE(TrackSequence(Basis(), views, 20, alone, &without, &MeshBasis()).ok());
  TrackOptions dense;
  dense.mesh_weight = 0.4;
  ASSERT_TRUE(TrackSequence(Basis(), views, 20, dense, &with, &MeshBasis()).ok());
  const Scores a = Score(truth, without), b = Score(truth, with);
  std::printf("68 points at 3 px: rotation %.2f deg, expression MAE %.3f; with the mesh at 1 px: %.2f deg, %.3f\n",
              a.rotation_deg, a.expression_mae, b.rotation_deg, b.expression_mae);
  EXPECT_LT(b.rotation_deg, 0.7 * a.rotation_deg);
  EXPECT_LT(b.expression_mae, a.expression_mae);
  // Frame 3's mesh moved right by 4 px: its fitted head follows it (the 68
  // points alone do not see it).
  std::vector<TrackingView> moved = views;
  for (Eigen::Vector2d& p : moved[3].mesh) p.x() += 4.0;
  TrackResult shifted, ignored;
  ASSERT_TRUE(TrackSequence(Basis(), moved, 20, dense, &shifted, &MeshBasis()).ok());
  ASSERT_TRUE(TrackSequence(Basis(), moved, 20, alone, &ignored, &MeshBasis()).ok());
  const double x_mesh = shifted.frames[3].head_motion.translation().x() - with.frames[3].head_motion.translation().x();
  const double x_alone = ignored.frames[3].head_motion.translation().x() - without.frames[3].head_motion.translation().x();
  EXPECT_GT(std::abs(x_mesh), 1e-4);  // metres: 4 px at 0.6 m and 900 px is 2.7 mm, shared with the 68 points
  EXPECT_EQ(x_alone, 0.0);
}

// A grid's node weights: one node on a grid line crossing, the four around a
// direction between them in proportion, clamped beyond the grid's edges.
TEST(LandmarkEmbedding, NodeWeightsAreBilinearAndClamped) {
  LandmarkEmbedding e;
  e.yaw_deg = {-20, 0, 20};
  e.pitch_deg = {-10, 10};
  e.nodes.assign(6, std::vector<Eigen::Vector3d>(68, Eigen::Vector3d::Zero()));
  auto toward = [](double yaw, double pitch) {
    const double y = yaw * M_PI / 180, p = pitch * M_PI / 180;
    return Eigen::Vector3d(std::cos(p) * std::sin(y), std::sin(p), std::cos(p) * std::cos(y));
  };
  auto weights = e.NodeWeights(toward(0, -10));
  ASSERT_EQ(weights.size(), 1u);
  EXPECT_EQ(weights[0].first, 1);
  EXPECT_NEAR(weights[0].second, 1.0, 1e-9);
  weights = e.NodeWeights(toward(5, 0) * 3.0);  // the length does not matter
  ASSERT_EQ(weights.size(), 4u);
  std::map<int, double> w(weights.begin(), weights.end());
  EXPECT_NEAR(w[1], 0.375, 1e-9);  // (yaw 0, pitch -10)
  EXPECT_NEAR(w[2], 0.125, 1e-9);  // (yaw 20, pitch -10)
  EXPECT_NEAR(w[4], 0.375, 1e-9);  // (yaw 0, pitch 10)
  EXPECT_NEAR(w[5], 0.125, 1e-9);  // (yaw 20, pitch 10)
  weights = e.NodeWeights(toward(70, 40));
  ASSERT_EQ(weights.size(), 1u);
  EXPECT_EQ(weights[0].first, 5);
}

// Points that slide over the surface as the identity changes: each point
// moves by the surface's columns S plus its own D (about 1 mm per standard
// deviation, as far as the detector's points move on real renders), seen with
// 0.3 mm of noise on 40 subjects. The ridge fit recovers S + D well enough to
// predict new subjects' points far better than the surface alone, its
// leave-one-out estimate says so too, and the columns reach the tracker's
// basis through the embedding file.
TEST(IdentityLandmarks, RidgeRecoversHowPointsSlideWithIdentity) {
  const LandmarkBasis& surface = Basis();
  const int modes = 20;
  std::mt19937 rng(7);
  std::normal_distribution<double> normal;
  std::vector<Eigen::Matrix<double, 3, Eigen::Dynamic>> slide(68);
  std::vector<Eigen::Vector3d> offset(68);
  for (int i = 0; i < 68; ++i) {
    slide[i] = Eigen::MatrixXd::NullaryExpr(3, modes, [&] { return 0.25e-3 * normal(rng); });
    offset[i] = Eigen::Vector3d(normal(rng), normal(rng), normal(rng)) * 1e-3;
  }
  auto truth = [&](int i, const Eigen::VectorXd& alpha) -> Eigen::Vector3d {
    return surface.base.col(i) + offset[i] + (surface.identity[i].leftCols(modes) + slide[i]) * alpha;
  };
  auto draw_alpha = [&] { return Eigen::VectorXd(Eigen::VectorXd::NullaryExpr(modes, [&] { return normal(rng); })); };
  std::vector<SubjectLandmarks> subjects(40);
  for (int s = 0; s < 40; ++s) {
    subjects[s].alpha = draw_alpha();
    subjects[s].seen.assign(68, 60);
    for (int i = 0; i < 68; ++i)
      subjects[s].points.push_back(truth(i, subjects[s].alpha) + 0.3e-3 * Eigen::Vector3d(normal(rng), normal(rng), normal(rng)));
  }
  for (int s = 0; s < 5; ++s) subjects[s].seen[0] = 3;  // too few renders: left out of landmark 0's fit
  subjects[0].points[0] = Eigen::Vector3d(1, 1, 1);     // which would otherwise spoil it

  LandmarkEmbedding fitted;
  IdentityFitReport report;
  ASSERT_TRUE(FitIdentityLandmarks(surface, subjects, modes, 10, &fitted, &report).ok());
  ASSERT_EQ(fitted.identity.size(), 68u);
  EXPECT_EQ(report.subjects, 40);
  std::printf("leave-one-out median %.3f mm (%.3f mm riding on the surface), lambda %.0f\n", 1e3 * report.loo_median,
              1e3 * report.loo_median_surface, report.lambda);
  EXPECT_LT(report.loo_median, 0.5 * report.loo_median_surface);

  // New subjects: the fitted points against the surface's motion alone.
  std::vector<double> fitted_err, surface_err;
  for (int s = 0; s < 20; ++s) {
    const Eigen::VectorXd alpha = draw_alpha();
    for (int i = 0; i < 68; ++i) {
      fitted_err.push_back((fitted.points[i] + fitted.identity[i] * alpha - truth(i, alpha)).norm());
      surface_err.push_back((surface.base.col(i) + offset[i] + surface.identity[i].leftCols(modes) * alpha - truth(i, alpha)).norm());
    }
  }
  std::sort(fitted_err.begin(), fitted_err.end());
  std::sort(surface_err.begin(), surface_err.end());
  const double fitted_median = fitted_err[fitted_err.size() / 2], surface_median = surface_err[surface_err.size() / 2];
  std::printf("new subjects: fitted %.3f mm, surface %.3f mm\n", 1e3 * fitted_median, 1e3 * surface_median);
  EXPECT_LT(fitted_median, 0.4 * surface_median);
  EXPECT_LT(fitted_err.back(), 3e-3);  // landmark 0 kept its outlier out

  // Written, read back and built into the tracker's basis: the columns are the fitted ones.
  const std::string path = (fs::temp_directory_path() / "hf_identity_embedding.json").string();
  ASSERT_TRUE(WriteLandmarkEmbedding(path, fitted).ok());
  LandmarkEmbedding read;
  ASSERT_TRUE(ReadLandmarkEmbedding(path, &read).ok());
  ASSERT_EQ(read.identity.size(), 68u);
  ViewLandmarkBases bases;
  ASSERT_TRUE(BuildViewLandmarkBases(Model(), read, 20, &bases).ok());
  for (int i = 0; i < 68; i += 7) {
    EXPECT_LT((bases.any_view.identity[i] - fitted.identity[i]).cwiseAbs().maxCoeff(), 1e-7) << i;
    EXPECT_LT((bases.any_view.base.col(i) - fitted.points[i]).norm(), 1e-6) << i;
  }

  // Too few subjects saw a landmark: a clear error.
  for (int s = 0; s < 35; ++s) subjects[s].seen[5] = 0;
  const Status few = FitIdentityLandmarks(surface, subjects, modes, 10, &fitted, &report);
  EXPECT_FALSE(few.ok());
  EXPECT_NE(few.message().find("landmark 5"), std::string::npos) << few.message();
}

// The detector's points differ with the view: here each turned camera sees
// the jaw contour 8 mm toward itself and the eye corners 2 mm lower. Fitted
// with one set of points for every view, no head fits all views (the
// residual triples, 0.34 -> 0.96 px); with each view's own points (a grid
// blended per camera) the fit is exact again, down to the noise.
TEST(Tracker, ViewDependentPointsFitViewsFromEverySide) {
  LandmarkEmbedding e;
  for (int i = 0; i < 68; ++i) e.points.push_back(Basis().base.col(i));
  e.yaw_deg = {-30, 0, 30};
  e.pitch_deg = {0};
  for (double yaw : e.yaw_deg) {
    std::vector<Eigen::Vector3d> points = e.points;
    const double side = yaw / 30.0;
    for (int i = 0; i < 17; ++i) points[i].x() += 0.008 * side;
    for (int i : {36, 39, 42, 45}) points[i].y() -= 0.002 * std::abs(side);
    e.nodes.push_back(points);
  }
  ViewLandmarkBases bases;
  ASSERT_TRUE(BuildViewLandmarkBases(Model(), e, 20, &bases).ok());
  ASSERT_EQ(bases.nodes.size(), 3u);
  const Eigen::Vector3d left = CameraAt(-30).rotation.transpose() * -CameraAt(-30).translation;
  EXPECT_LT((bases.ForDirection(left).base - bases.nodes[0].base).norm(), 1e-9);

  const Truth truth = MakeTruth(20, 0.0, 7);  // the head still: each view's direction is its camera's
  std::vector<TrackingCamera> cameras = {CameraAt(-30), CameraAt(0), CameraAt(30)};
  std::vector<TrackingView> views;
  std::mt19937 rng(8);
  std::normal_distribution<double> n(0.0, 0.3);
  for (int f = 0; f < 20; ++f) {
    for (const TrackingCamera& c : cameras) {
      TrackingView v;
      v.frame = f;
      v.camera = c;
      v.basis = std::make_shared<const LandmarkBasis>(bases.ForDirection(c.rotation.transpose() * -c.translation));
      std::array<Eigen::Vector2d, 68> points;
      for (int i = 0; i < 68; ++i) points[i] = c.Pixel(v.basis->Point(i, truth.alpha, truth.beta[f])) + Eigen::Vector2d(n(rng), n(rng));
      v.landmarks = points;
      views.push_back(v);
    }
  }
  TrackOptions options;
  options.contour_max_yaw_deg = 180;  // every view's contour counts
  TrackResult own, shared;
  ASSERT_TRUE(TrackSequence(Basis(), views, 20, options, &own).ok());
  for (auto& v : views) v.basis.reset();
  ASSERT_TRUE(TrackSequence(Basis(), views, 20, options, &shared).ok());
  const Scores a = Score(truth, own), b = Score(truth, shared);
  std::printf("each view's points: residual %.2f px, rotation %.2f deg; one set: %.2f px, %.2f deg\n", a.residual,
              a.rotation_deg, b.residual, b.rotation_deg);
  EXPECT_LT(a.residual, 0.5);
  EXPECT_LT(a.rotation_deg, 0.3);
  EXPECT_GT(b.residual, a.residual + 0.3);
}

// On views turned 30 degrees the detector draws the jaw contour along the
// silhouette, which does not follow the jaw as the frontal definition does:
// here the turned views' contour stays where a closed mouth puts it.
// Counted, it holds the jaw shut; left out of the turned views, the jaw comes
// from the frontal view's contour and the lips.
TEST(Tracker, TurnedViewsLeaveTheirJawContourOut) {
  const Truth truth = MakeTruth(20, 0.5, 40);
  auto views = Observe(truth, {CameraAt(-30), CameraAt(0), CameraAt(30)}, 0.3, 41);
  const int jaw = Model().ExpressionIndex("jawOpen");
  for (auto& v : views) {
    if (v.camera.rotation.isApprox(CameraAt(0).rotation)) continue;
    Eigen::VectorXd closed = truth.beta[v.frame];
    closed[jaw] = 0.0;
    for (int i = 0; i < 17; ++i) {
      const Eigen::Vector3d p =
          v.camera.rotation * (truth.motion[v.frame] * Basis().Point(i, truth.alpha, closed)) + v.camera.translation;
      (*v.landmarks)[i] =
          Eigen::Vector2d(v.camera.fx * p.x() / p.z() + v.camera.cx, v.camera.fy * p.y() / p.z() + v.camera.cy);
    }
  }
  double jaw_mae[2];
  for (int left_out = 0; left_out < 2; ++left_out) {
    TrackOptions options;
    options.contour_max_yaw_deg = left_out ? TrackOptions().contour_max_yaw_deg : 180.0;
    TrackResult result;
    ASSERT_TRUE(TrackSequence(Basis(), views, 20, options, &result).ok());
    jaw_mae[left_out] = 0;
    for (size_t f = 0; f < truth.beta.size(); ++f)
      jaw_mae[left_out] += std::abs(result.frames[f].expression[jaw] - truth.beta[f][jaw]) / truth.beta.size();
    std::printf("turned views' contour %s: jawOpen MAE %.3f\n", left_out ? "left out" : "counted", jaw_mae[left_out]);
  }
  EXPECT_GT(jaw_mae[0], 2 * jaw_mae[1]);
  EXPECT_LT(jaw_mae[1], 0.05);
}

// A detector failure in one camera (its landmarks scrambled by tens of
// pixels) and near-profile cameras are left out of the fit.
TEST(Tracker, DisagreeingAndNearProfileViewsAreLeftOut) {
  const Truth truth = MakeTruth(20, 1.0, 30);
  auto views = Observe(truth, {CameraAt(-25), CameraAt(0), CameraAt(25), CameraAt(70)}, 0.5, 31);
  std::mt19937 rng(32);
  std::normal_distribution<double> wild(0.0, 25.0);
  for (auto& v : views) {
    if (v.camera.rotation.isApprox(CameraAt(25).rotation) && v.frame % 2 == 0) {
      for (auto& p : *v.landmarks) p += Eigen::Vector2d(wild(rng), wild(rng));
    }
    if (v.camera.rotation.isApprox(CameraAt(70).rotation)) {
      for (auto& p : *v.landmarks) p += Eigen::Vector2d(30, -20);  // a consistently wrong profile
    }
  }
  TrackResult result;
  ASSERT_TRUE(TrackSequence(Basis(), views, 20, TrackOptions(), &result).ok());
  EXPECT_EQ(result.dropped_views, 10);
  const Scores s = Score(truth, result);
  std::printf("with bad views: residual %.2f px, expression MAE %.3f, rotation %.2f deg\n", s.residual,
              s.expression_mae, s.rotation_deg);
  EXPECT_LT(s.residual, 1.0);
  EXPECT_LT(s.expression_mae, 0.06);
  EXPECT_LT(s.rotation_deg, 0.5);
}

// One fixed camera whose focal length is given 30% long (with its distance
// scaled to match, so the face keeps its size in the image): fitting the
// focal length with the identity and expressions recovers it, where the
// perspective across the face is the only cue.
TEST(Tracker, FocalLengthIsRecoveredWithTheWholeFaceModel) {
  const Truth truth = MakeTruth(60, 1.0, 21);
  const TrackingCamera real = CameraAt(0, 900, 0.6);
  const std::vector<TrackingView> observed = Observe(truth, {real}, 0.5, 22);
  std::vector<TrackingView> views = observed;
  for (TrackingView& v : views) v.camera = CameraAt(0, 1170, 0.78);
  TrackOptions options;
  options.threads = 2;
  options.max_iterations = 300;
  TrackResult held, fitted;
  ASSERT_TRUE(TrackSequence(Basis(), views, 60, options, &held).ok());
  options.fit_focal = true;
  ASSERT_TRUE(TrackSequence(Basis(), views, 60, options, &fitted).ok());
  const double focal = 1170 * fitted.focal_scale;
  std::printf("focal given 1170 px, true 900: fitted %.1f px; residual %.3f px (focal held: %.3f px)\n", focal,
              fitted.median_residual_px, held.median_residual_px);
  EXPECT_NEAR(focal, 900, 0.03 * 900);
  EXPECT_LT(fitted.median_residual_px, held.median_residual_px);
  EXPECT_DOUBLE_EQ(held.focal_scale, 1.0);
  // The head is held by the cameras: the focal length cannot be refined.
  options.fixed_head = true;
  TrackResult refused;
  EXPECT_FALSE(TrackSequence(Basis(), views, 60, options, &refused).ok());
}

// A head that holds still (only its expressions move) seen through a long
// lens from afar, a broadcast close-up: the perspective across a face of
// free identity hardly fixes the focal length there, the reported
// uncertainty says so, and a prior toward an ordinary lens moves it there.
TEST(Tracker, AStillHeadLeavesTheFocalLengthLooseAndThePriorPullsIt) {
  TrackOptions options;
  options.threads = 2;
  options.fit_focal = true;
  options.focal_uncertainty = true;
  const Truth truth = MakeTruth(12, 0.0, 21);
  std::vector<TrackingView> views = Observe(truth, {CameraAt(0, 3000, 1.8)}, 1.0, 22);
  for (TrackingView& v : views) v.camera = CameraAt(0, 3900, 2.34);
  TrackResult free, held;
  ASSERT_TRUE(TrackSequence(Basis(), views, 12, options, &free).ok());
  options.focal_prior_scale = 1000.0 / 3900;  // centred on 1000 px
  ASSERT_TRUE(TrackSequence(Basis(), views, 12, options, &held).ok());
  std::printf("still head, true focal 3000 px: %.0f px (+-%.1f%%); with a prior at 1000 px: %.0f px (+-%.1f%%)\n",
              3900 * free.focal_scale, 100 * free.focal_log_sigma, 3900 * held.focal_scale, 100 * held.focal_log_sigma);
  // Loose: several percent (a turning head at 0.6 m: about 1 %, the test above).
  EXPECT_GT(free.focal_log_sigma, 0.05);
  EXPECT_LT(held.focal_scale, free.focal_scale);
  EXPECT_LT(held.focal_log_sigma, free.focal_log_sigma);
}

TEST(Tracker, HeadHeldByTheCamerasStaysFixed) {
  // Head-pose calibration: each frame's camera carries the head's motion.
  Truth truth = MakeTruth(20, 1.0, 5);
  std::vector<TrackingView> views;
  for (int f = 0; f < 20; ++f) {
    TrackingCamera c = CameraAt(0);
    Truth still = truth;
    const Eigen::Isometry3d motion = truth.motion[f];
    c.translation = c.rotation * motion.translation() + c.translation;
    c.rotation = c.rotation * motion.linear();
    still.motion.assign(20, Eigen::Isometry3d::Identity());
    auto v = Observe(still, {c}, 0.3, 6 + f);
    views.push_back(v[f]);
  }
  TrackOptions options;
  options.fixed_head = true;
  TrackResult result;
  ASSERT_TRUE(TrackSequence(Basis(), views, 20, options, &result).ok());
  for (const auto& f : result.frames) EXPECT_TRUE(f.head_motion.isApprox(Eigen::Isometry3d::Identity()));
  EXPECT_LT(result.median_residual_px, 0.8);
}

// Cameras that carry each frame's motion but sit on a head frame turned and
// shifted by one constant error (head-pose cameras whose motion features
// refined, their head frame from the landmarks' mean): one head motion for
// all frames finds that error, the same in every frame, frames without
// landmarks included.
TEST(Tracker, OneHeadMotionMovesTheHeadFrameAlikeInEveryFrame) {
  const Truth truth = MakeTruth(30, 1.0, 15);
  Eigen::Isometry3d error = Eigen::Isometry3d::Identity();
  error.linear() = (Eigen::AngleAxisd(2.0 * M_PI / 180, Eigen::Vector3d::UnitX()) *
                    Eigen::AngleAxisd(-1.0 * M_PI / 180, Eigen::Vector3d::UnitY()))
                       .toRotationMatrix();
  error.translation() = Eigen::Vector3d(0.002, -0.003, 0.001);
  std::vector<TrackingView> views;
  for (int f = 0; f < 30; ++f) {
    Truth still = truth;
    still.motion.assign(30, Eigen::Isometry3d::Identity());
    TrackingCamera c = CameraAt(0);
    const Eigen::Isometry3d motion = truth.motion[f];
    c.translation = c.rotation * motion.translation() + c.translation;
    c.rotation = c.rotation * motion.linear();
    TrackingView v = Observe(still, {c}, 0.3, 40 + f)[size_t(f)];
    // The given camera: cam_from_head * error.
    v.camera.translation = v.camera.rotation * error.translation() + v.camera.translation;
    v.camera.rotation = v.camera.rotation * error.linear();
    views.push_back(v);
  }
  views[12].landmarks.reset();
  TrackOptions options;
  options.one_head_motion = true;
  TrackResult result;
  ASSERT_TRUE(TrackSequence(Basis(), views, 30, options, &result).ok());
  // given * motion = true: the motion undoes the error.
  const Eigen::Isometry3d undo = error.inverse();
  for (const TrackedFrame& f : result.frames) {
    EXPECT_TRUE(f.head_motion.isApprox(result.frames[0].head_motion, 1e-12)) << f.frame;
  }
  const double turn = RotationErrorDeg(result.frames[12].head_motion, undo);
  const double shift_mm = 1000 * (result.frames[12].head_motion.translation() - undo.translation()).norm();
  std::printf("one head motion: %.3f deg and %.2f mm from the error it undoes (2.2 deg, 3.7 mm); residual %.2f px\n",
              turn, shift_mm, result.median_residual_px);
  EXPECT_LT(turn, 0.3);
  EXPECT_LT(shift_mm, 2.0);
  EXPECT_LT(result.median_residual_px, 0.8);
  options.fixed_head = true;  // holding the head and moving it: refused
  EXPECT_FALSE(TrackSequence(Basis(), views, 30, options, &result).ok());
}

TEST(Tracker, FramesWithoutLandmarksAreInterpolatedAndFlagged) {
  const Truth truth = MakeTruth(30, 1.0, 7);
  auto views = Observe(truth, {CameraAt(0)}, 0.5, 8);
  for (int f : {0, 10, 11, 12, 29}) views[f].landmarks.reset();
  TrackResult result;
  ASSERT_TRUE(TrackSequence(Basis(), views, 30, TrackOptions(), &result).ok());
  for (int f : {0, 10, 11, 12, 29}) {
    EXPECT_TRUE(result.frames[f].interpolated && result.frames[f].low_confidence) << f;
    EXPECT_EQ(result.frames[f].landmarks, 0);
  }
  // Interpolated frames sit between their neighbours.
  const double j = Model().ExpressionIndex("jawOpen");
  const double a = result.frames[9].expression[j], b = result.frames[13].expression[j];
  EXPECT_NEAR(result.frames[11].expression[j], 0.5 * (a + b), 1e-9);
  EXPECT_LT(RotationErrorDeg(result.frames[11].head_motion, truth.motion[11]), 2.0);
}

TEST(Tracker, NoLandmarksAtAllIsAClearError) {
  const Truth truth = MakeTruth(5, 1.0, 9);
  auto views = Observe(truth, {CameraAt(0)}, 0.5, 10);
  for (auto& v : views) v.landmarks.reset();
  TrackResult result;
  const Status s = TrackSequence(Basis(), views, 5, TrackOptions(), &result);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("no frame has landmarks"), std::string::npos);
}

// Hard cases: finite results, flagged where the data cannot support them.
bool AllFinite(const TrackResult& r) {
  if (!r.identity.allFinite()) return false;
  for (const auto& f : r.frames) {
    if (!f.expression.allFinite() || !f.head_motion.matrix().allFinite()) return false;
  }
  return true;
}

TEST(TrackerHardCases, LargeYawWithTheFarSideHidden) {
  for (double yaw : {-80.0, 80.0}) {
    const Truth truth = MakeTruth(10, 0.3, 11);
    auto views = Observe(truth, {CameraAt(yaw)}, 0.5, 12);
    // Landmarks on the side turned away (head-frame x against the camera) are unseen.
    for (auto& v : views) {
      v.confidence.assign(68, 1.0);
      for (int i = 0; i < 68; ++i) {
        if (Basis().base(0, i) * yaw < -0.005) v.confidence[i] = 0.0;
      }
    }
    TrackResult result;
    ASSERT_TRUE(TrackSequence(Basis(), views, 10, TrackOptions(), &result).ok()) << yaw;
    EXPECT_TRUE(AllFinite(result));
    for (const auto& f : result.frames) {
      EXPECT_TRUE(f.low_confidence) << yaw;
      EXPECT_NE(f.why.find("profile view"), std::string::npos) << f.why;
    }
    EXPECT_LT(Score(truth, result).rotation_deg, 5.0) << yaw;
  }
}

TEST(TrackerHardCases, HalfTheLandmarksMissing) {
  const Truth truth = MakeTruth(20, 1.0, 13);
  auto views = Observe(truth, {CameraAt(0)}, 0.5, 14);
  std::mt19937 rng(15);
  for (auto& v : views) {
    v.confidence.assign(68, 1.0);
    std::vector<int> order(68);
    std::iota(order.begin(), order.end(), 0);
    std::shuffle(order.begin(), order.end(), rng);
    for (int i = 0; i < 34; ++i) v.confidence[order[i]] = 0.0;
  }
  TrackResult result;
  ASSERT_TRUE(TrackSequence(Basis(), views, 20, TrackOptions(), &result).ok());
  EXPECT_TRUE(AllFinite(result));
  const Scores s = Score(truth, result);
  EXPECT_LT(s.rotation_deg, 2.0);
  EXPECT_LT(s.expression_mae, 0.15);
}

TEST(TrackerHardCases, NearlyCollinearLandmarksAreFlagged) {
  // Only the nose bridge and chin (points 27-30 and 8) in a profile view.
  const Truth truth = MakeTruth(8, 0.3, 16);
  auto views = Observe(truth, {CameraAt(85)}, 0.3, 17);
  for (auto& v : views) {
    v.confidence.assign(68, 0.0);
    for (int i : {8, 27, 28, 29, 30}) v.confidence[i] = 1.0;
  }
  TrackResult result;
  ASSERT_TRUE(TrackSequence(Basis(), views, 8, TrackOptions(), &result).ok());
  EXPECT_TRUE(AllFinite(result));
  for (const auto& f : result.frames) {
    EXPECT_TRUE(f.low_confidence);
    EXPECT_NE(f.why.find("few landmarks"), std::string::npos) << f.why;
  }
}

TEST(TrackerHardCases, NoMotionAndAVeryLongFocalLength) {
  // A still head seen through a 50 000 px lens from 30 m: nearly orthographic.
  const Truth truth = MakeTruth(10, 0.0, 18);
  const auto views = Observe(truth, {CameraAt(0, 50000, 30.0)}, 0.5, 19);
  TrackResult result;
  ASSERT_TRUE(TrackSequence(Basis(), views, 10, TrackOptions(), &result).ok());
  EXPECT_TRUE(AllFinite(result));
  const Scores s = Score(truth, result);
  EXPECT_LT(s.residual, 1.0);
  EXPECT_LT(s.rotation_deg, 1.0);
}

// The track stage takes cameras as calibrate wrote them, lens distortion
// included (COLMAP's SIMPLE_RADIAL, OPENCV), and removes it from the landmarks
// before the pinhole fit: landmarks seen through a lens then track exactly as
// the same landmarks seen through a pinhole do. The face sits off the lens
// axis, where a k1 of -0.25 moves its landmarks by several pixels.
TEST(TrackStage, RemovesLensDistortionFromTheLandmarks) {
  const int frames = 12;
  const Truth truth = MakeTruth(frames, 0.3, 21);
  TrackingCamera pinhole = CameraAt(0, 900, 0.6);
  pinhole.translation.x() += 0.15;  // a quarter of the distance off the axis
  CameraIntrinsics lens;
  lens.name = "cam0";
  lens.model = "OPENCV";
  lens.width = lens.height = 512;
  lens.fx = lens.fy = pinhole.fx;
  lens.cx = pinhole.cx;
  lens.cy = pinhole.cy;
  lens.k1 = -0.25;
  lens.k2 = 0.05;
  lens.p1 = 0.002;
  CameraIntrinsics no_lens = lens;
  no_lens.model = "PINHOLE";
  no_lens.k1 = no_lens.k2 = no_lens.p1 = 0;

  // One capture per way of seeing the landmarks, with the cameras that go with it.
  std::vector<double> shift;
  auto make = [&](const CameraIntrinsics& seen_through, const CameraIntrinsics& calibrated, IngestedCapture* capture,
                  CameraSet* cameras) {
    IngestedCamera cam;
    cam.name = "cam0";
    cam.width = cam.height = 512;
    cameras->mode = "colmap";
    cameras->frame = "head";
    cameras->cameras = {calibrated};
    for (int f = 0; f < frames; ++f) {
      IngestedFrame frame;
      frame.index = f;
      Landmarks68 points;
      for (int i = 0; i < 68; ++i) {
        const Eigen::Vector3d head = truth.motion[f] * Basis().Point(i, truth.alpha, truth.beta[f]);
        const Eigen::Vector2d px = seen_through.Project(pinhole.rotation * head + pinhole.translation);
        points[i] = cv::Point2f(float(px.x()), float(px.y()));
        shift.push_back((px - pinhole.Pixel(head)).norm());
      }
      frame.landmarks = points;
      cam.frames.push_back(frame);
      CameraView view;
      view.camera = "cam0";
      view.frame = f;
      view.registered = true;
      view.cam_from_world.linear() = pinhole.rotation;
      view.cam_from_world.translation() = pinhole.translation;
      cameras->views.push_back(view);
    }
    capture->cameras = {cam};
  };
  TrackStageOptions options;
  options.overlay = false;
  const fs::path out = fs::temp_directory_path() / "hf_track_lens";
  fs::remove_all(out);
  fs::create_directories(out);
  NullProgress progress;
  // Tracks; returns every frame's 53 weights.
  auto track = [&](const IngestedCapture& capture, const CameraSet& cameras) {
    fs::remove(out / "tracking.json");
    TrackSummary summary;
    EXPECT_TRUE(RunTrack(options, capture, cameras, Model(), out, &progress, &summary).ok());
    nlohmann::json j;
    EXPECT_TRUE(ReadJson(out / "tracking.json", &j).ok());
    std::vector<double> weights;
    for (const auto& f : j["frames"])
      for (const auto& name : Model().expression_names()) weights.push_back(f["expression"][name].get<double>());
    return weights;
  };
  auto max_difference = [](const std::vector<double>& a, const std::vector<double>& b) {
    EXPECT_EQ(a.size(), b.size());
    EXPECT_EQ(a.size(), size_t(frames) * Model().num_expressions());
    double d = 0;
    for (size_t i = 0; i < std::min(a.size(), b.size()); ++i) d = std::max(d, std::abs(a[i] - b[i]));
    return d;
  };

  IngestedCapture clean, distorted;
  CameraSet clean_cameras, lens_cameras, pinhole_cameras;
  make(no_lens, no_lens, &clean, &clean_cameras);
  shift.clear();
  make(lens, lens, &distorted, &lens_cameras);
  make(lens, no_lens, &distorted, &pinhole_cameras);
  std::nth_element(shift.begin(), shift.begin() + shift.size() / 2, shift.end());
  ASSERT_GT(shift[shift.size() / 2], 3.0) << "the lens should move the landmarks by pixels";

  const std::vector<double> reference = track(clean, clean_cameras);
  const double with_lens = max_difference(track(distorted, lens_cameras), reference);
  const double without_lens = max_difference(track(distorted, pinhole_cameras), reference);
  EXPECT_LT(with_lens, 0.002);
  EXPECT_GT(without_lens, 0.02);  // the check above is not vacuous
}

}  // namespace
}  // namespace headforge
