// Calibrate and align on real inputs: COLMAP on a simulated orbit (checked
// against the ground truth), head-pose cameras on a GRID clip, the auto mode's
// fallback, rig import, and COLMAP failing clearly on frames it cannot use.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <cmath>
#include <cstring>
#include <map>
#include <random>
#include <set>

#include <opencv2/imgcodecs.hpp>

#include "calibration/align.h"
#include "calibration/calibrate.h"
#include "calibration/colmap_runner.h"
#include "calibration/evaluation.h"
#include "calibration/face_points.h"
#include "capture/ingest.h"
#include "capture/simulator.h"
#include "core/fs.h"
#include "core/json_io.h"
#include "core/mesh_renderer.h"
#include "core/paths.h"
#include "core/statistics.h"
#include "tests/calibrate_fixture.h"

namespace headforge {
namespace {

// A scene file of the repository's scenes/.
std::string SceneFile(const std::string& name) {
  std::string text;
  EXPECT_TRUE(ReadFileToString(fs::path(HEADFORGE_TEST_SOURCE_DIR) / "scenes" / name, &text).ok()) << name;
  return text;
}

// scenes/small_orbit.toml: 24 frames 15 degrees apart at 320 px.
std::string SmallOrbit() { return SceneFile("small_orbit.toml"); }

// Ingest's default crop keeps a moving camera's frames whole for COLMAP: it
// crops around the head, sees the background move, and writes them again.
TEST(Calibrate, IngestKeepsAMovingCamerasFramesWhole) {
  const fs::path dir = Scratch("orbit_auto_crop");
  IngestedCapture capture;
  nlohmann::json truth;
  IngestSummary summary;
  SimulateAndIngest(SmallOrbit(), dir, &capture, &truth, {}, "auto", &summary);
  EXPECT_EQ(summary.crop, "none");
  ASSERT_EQ(capture.cameras.size(), 1u);
  EXPECT_EQ(capture.cameras[0].width, 320);
  EXPECT_DOUBLE_EQ(capture.cameras[0].crop_x0, 0.0);
  EXPECT_DOUBLE_EQ(capture.cameras[0].crop_scale, 1.0);
  EXPECT_EQ(capture.num_frames(), 24);
  EXPECT_EQ(summary.with_landmarks + summary.face_lost, 24);  // counted once, not per writing
  // Every frame and mask was written whole (none left from the first, cropped writing).
  EXPECT_EQ(ListFiles(dir / "workspace" / "frames" / "cam0").size(), 24u);
  const cv::Mat mask = cv::imread(capture.MaskPath("cam0", 23).string(), cv::IMREAD_GRAYSCALE);
  EXPECT_EQ(mask.size(), cv::Size(320, 320));
}

// scenes/head_turn.toml (a fixed camera, a plain backdrop, the head turning
// +-40 degrees) made small: 256 px, 5 frames a second (25 frames).
std::string SmallHeadTurn() {
  std::string text = SceneFile("head_turn.toml");
  auto replace = [&](const std::string& from, const std::string& to) {
    const size_t at = text.find(from);
    EXPECT_NE(at, std::string::npos) << from;
    if (at != std::string::npos) text.replace(at, from.size(), to);
  };
  replace("fps = 25", "fps = 5");
  replace("width = 512", "width = 256");
  replace("height = 512", "height = 256");
  replace("focal = 1100.0", "focal = 550.0");
  return text;
}

// A head that turns freely before a fixed camera moves hair, ears and
// shoulders across the frame; ingest's auto crop and calibrate's auto mode
// must still judge the camera fixed (the background is measured outside
// the person's matte), crop round the head and give head-pose cameras.
TEST(Calibrate, ATurningHeadBeforeAPlainWallIsAFixedCamera) {
  const fs::path dir = Scratch("head_turn");
  IngestedCapture capture;
  nlohmann::json truth;
  IngestSummary summary;
  SimulateAndIngest(SmallHeadTurn(), dir, &capture, &truth, {}, "auto", &summary);
  EXPECT_EQ(summary.crop, "sequence");
  ASSERT_EQ(capture.num_frames(), 25);
  // The network's matte holds the turned heads too: hair and ears are not
  // taken for background.
  EXPECT_GE(summary.with_landmarks, 20);
  BackgroundMotion motion;
  ASSERT_TRUE(MeasureBackgroundMotion(capture, "cam0", &motion).ok());
  std::printf("head turn background: %s\n", motion.Describe().c_str());
  EXPECT_FALSE(motion.Moving(kMovingCameraPx));
  NullProgress progress;
  CalibrateOptions options;  // auto
  CameraSet cameras;
  CalibrateSummary result;
  const Status status = RunCalibrate(options, capture, Model(), dir / "out", &progress, &cameras, &result);
  ASSERT_TRUE(status.ok()) << status.message();
  EXPECT_EQ(result.mode, "head-pose");
  EXPECT_NE(result.reason.find("fixed camera"), std::string::npos) << result.reason;
  // What the matte is for: measured without it (the whole frame above the
  // mouth), the turning hair and ears read as a moving background.
  fs::remove_all(dir / "workspace" / "masks");
  BackgroundMotion unmasked;
  ASSERT_TRUE(MeasureBackgroundMotion(capture, "cam0", &unmasked).ok());
  std::printf("head turn without the matte: %s\n", unmasked.Describe().c_str());
  EXPECT_TRUE(unmasked.Moving(kMovingCameraPx));
}

TEST(Calibrate, ColmapRegistersEveryOrbitFrameAccurately) {
  const fs::path dir = Scratch("orbit");
  IngestedCapture capture;
  nlohmann::json truth;
  std::string scene = SmallOrbit();
  scene.replace(scene.find("frames = 24"), 11, "frames = 36");
  SimulateAndIngest(scene.c_str(), dir, &capture, &truth);
  // Auto mode sees the camera move: frames a quarter of the orbit apart share
  // no background that optical flow can follow, but the background changed.
  BackgroundMotion motion;
  ASSERT_TRUE(MeasureBackgroundMotion(capture, "cam0", &motion).ok());
  std::printf("orbit background: %s\n", motion.Describe().c_str());
  EXPECT_LT(motion.followed, 20);
  EXPECT_GT(motion.change, 8.0);
  EXPECT_TRUE(motion.Moving(1.5));
  CalibrateOptions options;
  options.mode = "colmap";
  options.colmap.executable = DefaultColmapExecutable();
  // The simulated lens has no distortion. With SIMPLE_RADIAL, this single
  // ring's focal length lands 5-24% off (COLMAP trades it against k1), and
  // align's scale with it (docs/calibration.md).
  options.colmap.camera_model = "SIMPLE_PINHOLE";
  CameraSet cameras;
  CalibrateSummary summary;
  NullProgress progress;
  const Status status = RunCalibrate(options, capture, Model(), dir / "out", &progress, &cameras, &summary);
  ASSERT_TRUE(status.ok()) << status.message();
  EXPECT_EQ(summary.mode, "colmap");
  EXPECT_GE(summary.registered, 33);  // COLMAP's multithreaded mapper varies a little from run to run
  EXPECT_TRUE(fs::exists(dir / "out" / "colmap" / "model" / "images.txt"));
  CameraSet reread;
  ASSERT_TRUE(CameraSet::Read(dir / "out" / "cameras.json", &reread).ok());
  EXPECT_EQ(reread.registered(), summary.registered);

  AlignResult aligned;
  const Status align = RunAlign(AlignOptions(), capture, cameras, Model(), &aligned);
  ASSERT_TRUE(align.ok()) << align.message();
  CameraErrors errors;
  ASSERT_TRUE(EvaluateWorldCameras(cameras, capture, truth, &aligned.head_from_world, &errors).ok());
  // The head frame against the truth, with align's surface fit and with the
  // landmarks alone.
  CameraErrors head, landmarks_head, landmarks_world;
  ASSERT_TRUE(EvaluateHeadCameras(aligned.cameras, capture, truth, &head).ok());
  ASSERT_TRUE(EvaluateHeadCameras(ToHeadFrame(cameras, aligned.landmarks_head_from_world), capture, truth,
                                  &landmarks_head)
                  .ok());
  ASSERT_TRUE(
      EvaluateWorldCameras(cameras, capture, truth, &aligned.landmarks_head_from_world, &landmarks_world).ok());
  std::printf("orbit: rotation %.3f deg, centre %.2f mm (median), focal %.2f%% off; %d revisit pairs (%s)\n"
              "orbit: surface fit on %d of %d points on the face: aligned rotation %.2f deg (landmarks alone %.2f), "
              "scale %.2f%% off (landmarks alone %.2f%%)\n",
              errors.median_rotation_deg, errors.median_centre_mm, 100 * errors.focal_error, summary.revisit_pairs,
              summary.reason.c_str(), aligned.surface_points, aligned.face_points, head.median_rotation_deg,
              landmarks_head.median_rotation_deg, 100 * errors.scale_error, 100 * landmarks_world.scale_error);
  // A small, low-resolution orbit: the full-size figures come from `headforge bench calibrate`.
  // Over seventeen runs (COLMAP's mapper differs run to run): rotation
  // 0.06-0.14 deg, centre 1.3-3.1 mm.
  EXPECT_LT(errors.median_rotation_deg, 0.6);
  EXPECT_LT(errors.median_centre_mm, 10.0);
  // The last frame comes back to 10 deg short of the first, a revisit that
  // sequential matching (ten neighbours) never pairs; calibrate matches it
  // and refines the model. When the first mapping registers too few frames,
  // every pair is matched instead and revisits are not looked for (three of
  // those runs found no pairs and took twice as long, as matching every pair
  // does). On this short orbit the drift is small either way
  // (six runs without revisits: 0.08-0.11 deg, 1.5-2.2 mm); on orbit_360's
  // three rings revisits take the median centre error from 3-31 mm to
  // 0.5-0.6 mm (README).
  if (summary.sequential_registered < 0) {
    EXPECT_GE(summary.revisit_pairs, 1);
  }
  EXPECT_TRUE(fs::exists(dir / "out" / "colmap" / "revisit_pairs.txt") || summary.sequential_registered >= 0);
  // Align's surface fit: some 2000 points triangulated on this small face
  // (320 pixels, one ring at eye level), 1400-1550 paired. Over six runs:
  // aligned rotation 0.70-1.23 deg, scale 0.5-3.5% off (the landmarks alone:
  // 3.4 deg and 5.9-6.0%, the mean face's size for a face 4.4% smaller, from
  // the few near-frontal views of this short orbit); with the whole suite
  // running beside it COLMAP's model varies more (a run at 1.48 deg and
  // 5.2%, landmarks alone 5.9%; another, on 1386 of 2096 points, at 1.59 deg
  // and 6.4%, landmarks alone 5.8%, where alone the same build gave 2.0% and
  // 3.3%): the fit must beat the landmarks' rotation, and its scale stays
  // within 7.5% and within a point of theirs. One ring at eye level pins
  // pitch less than orbit_360's three (docs/benchmarks.md).
  EXPECT_EQ(aligned.method, "views+reprojection+surface");
  EXPECT_GT(aligned.surface_points, 1000);
  EXPECT_LT(head.median_rotation_deg, 2.0);
  EXPECT_LT(head.median_rotation_deg, landmarks_head.median_rotation_deg);
  EXPECT_LT(errors.scale_error, 0.075);
  EXPECT_LT(errors.scale_error, landmarks_world.scale_error + 0.01);
  EXPECT_TRUE(std::isfinite(aligned.median_mm));
  // The re-expressed cameras keep their geometry: rigid, about the head.
  for (const auto& v : aligned.cameras.views) {
    if (!v.registered) continue;
    EXPECT_NEAR(v.cam_from_world.linear().determinant(), 1.0, 1e-9);
    EXPECT_NEAR(v.Centre().norm(), 0.8, 0.8 * 0.4);
  }
}

// Align's points on the face, triangulated through the true cameras of the
// small orbit (320 pixels, 24 frames 15 deg apart): some 800 from 13 views,
// 96% of them on the face, 0.7 mm from the subject's true surface (median).
TEST(FacePoints, LieOnTheTrueFace) {
  const fs::path dir = Scratch("face_points");
  IngestedCapture capture;
  nlohmann::json truth;
  SimulateAndIngest(SmallOrbit(), dir, &capture, &truth);
  CameraSet cameras;
  cameras.cameras = {CameraIntrinsics::FromJson(truth["cameras"][0])};  // cam0, no distortion
  for (const auto& frame : truth["frames"]) {
    CameraView view;
    view.camera = "cam0";
    view.frame = frame["index"].get<int>();
    view.registered = true;
    view.cam_from_world = PoseFromJson(frame["views"]["cam0"]["cam_from_world"]);
    cameras.views.push_back(view);  // the head stays at the world's origin: world = head frame
  }
  std::vector<Eigen::Vector3d> points;
  FacePointStats stats;
  ASSERT_TRUE(TriangulateFacePoints(capture, cameras, "cam0", FacePointOptions(), &points, &stats).ok());
  // The subject's surface: its fitting region's vertices and normals.
  Eigen::VectorXf alpha(static_cast<int>(truth["identity"].size()));
  for (int k = 0; k < alpha.size(); ++k) alpha(k) = truth["identity"][size_t(k)].get<float>();
  const Eigen::Matrix3Xf shape = Model().Identity(alpha);
  const Eigen::Matrix3Xf normals = VertexNormals(shape, Model().triangles());
  std::vector<double> distances;
  int near = 0;
  for (const Eigen::Vector3d& p : points) {
    double best = 1e9;
    int nearest = -1;
    for (int v : Model().fitting_vertices()) {
      const double d = (shape.col(v).cast<double>() - p).squaredNorm();
      if (d < best) best = d, nearest = v;
    }
    // Point to the nearest vertex's tangent plane (vertices lie some 2.4 mm apart).
    const double d = std::abs(normals.col(nearest).cast<double>().dot(p - shape.col(nearest).cast<double>()));
    distances.push_back(1000 * d);
    near += std::sqrt(best) < 0.01;
  }
  std::printf("face points: %d from %d pairs of %d views; %d within 10 mm of the face, median %.2f mm from it\n",
              stats.points, stats.pairs, stats.views, near, Median(distances));
  EXPECT_EQ(stats.points, static_cast<int>(points.size()));
  EXPECT_GE(stats.views, 8);
  EXPECT_GT(stats.points, 500);
  // The outline's margin reaches past the cheeks: a few percent of the points
  // lie on the room behind (the surface fit leaves them unpaired).
  EXPECT_GT(near, 0.9 * stats.points);
  EXPECT_LT(Median(distances), 1.0);
}

// A video that jumps between two sides of the head: sequential matching
// (one neighbour here) links no frames, so the mapper finds nothing; matching
// every pair after it recovers the orbit.
TEST(Calibrate, SequentialMatchingThatBreaksFallsBackToEveryPair) {
  const fs::path dir = Scratch("jumps");
  std::vector<int> order;
  for (int i = 0; i < 12; ++i) order.insert(order.end(), {i, i + 12});  // 0, 12, 1, 13, ...: 180 deg jumps
  IngestedCapture capture;
  nlohmann::json truth;
  SimulateAndIngest(SmallOrbit(), dir, &capture, &truth, order);
  CalibrateOptions options;
  options.mode = "colmap";
  options.colmap.executable = DefaultColmapExecutable();
  options.colmap.overlap = 1;
  CameraSet cameras;
  CalibrateSummary summary;
  NullProgress progress;
  options.colmap.exhaustive_fallback_max = 0;  // no fallback: calibrate fails
  const Status failed = RunCalibrate(options, capture, Model(), dir / "sequential", &progress, &cameras, &summary);
  ASSERT_FALSE(failed.ok());
  EXPECT_NE(failed.message().find("Try"), std::string::npos) << failed.message();

  options.colmap.exhaustive_fallback_max = ColmapOptions().exhaustive_fallback_max;
  const Status status = RunCalibrate(options, capture, Model(), dir / "fallback", &progress, &cameras, &summary);
  ASSERT_TRUE(status.ok()) << status.message();
  std::printf("sequential matching registered %d of 24, then every pair: %d (%s)\n", summary.sequential_registered,
              summary.registered, summary.reason.c_str());
  EXPECT_GE(summary.sequential_registered, 0);
  EXPECT_LT(summary.sequential_registered, 12);
  // COLMAP's mapper does not repeat itself run to run (3.8 seeds its threads
  // from the clock): 24 of 24 in most runs, 21 in one.
  EXPECT_GE(summary.registered, 18);
  EXPECT_NE(summary.reason.find("then every pair was matched"), std::string::npos) << summary.reason;
  CameraErrors errors;
  ASSERT_TRUE(EvaluateWorldCameras(cameras, capture, truth, nullptr, &errors).ok());
  std::printf("every pair: rotation %.2f deg, centre %.1f mm (median)\n", errors.median_rotation_deg,
              errors.median_centre_mm);
  // With every frame registered the orbit is accurate (0.08-0.09 deg, 1.3-1.6
  // mm in four runs); a model that left frames out was 6.6 deg off in one of
  // ten runs (21 of 24).
  EXPECT_LT(errors.median_rotation_deg, 10.0);
  if (summary.registered == 24) {
    EXPECT_LT(errors.median_rotation_deg, 1.0);
    EXPECT_LT(errors.median_centre_mm, 12.0);
  }
}

// Frames too close together for the mapper: matched with one neighbour
// each (--overlap 1), 6 degrees apart, no pair has the parallax the mapper
// starts from, and sequential mapping registers nothing (the walk-around
// video's 150 frames 2.4 degrees apart with ten neighbours fail the same way,
// too slowly for a test: `headforge bench calibrate --scenes walkaround_360
// --quick`). One image in three is mapped alone, with its next keyframe
// matched, and the images between are registered into that model; every
// pair is never matched here.
TEST(Calibrate, DenseFramesAreMappedAsKeyframesAndTheRestRegistered) {
  const fs::path dir = Scratch("dense");
  IngestedCapture capture;
  nlohmann::json truth;
  std::string scene = SmallOrbit();
  scene.replace(scene.find("frames = 24"), 11, "frames = 60");
  SimulateAndIngest(scene, dir, &capture, &truth);
  CalibrateOptions options;
  options.mode = "colmap";
  options.colmap.executable = DefaultColmapExecutable();
  options.colmap.overlap = 1;
  options.colmap.exhaustive_fallback_max = 0;
  CameraSet cameras;
  CalibrateSummary summary;
  NullProgress progress;
  const Status status = RunCalibrate(options, capture, Model(), dir / "keyframes", &progress, &cameras, &summary);
  ASSERT_TRUE(status.ok()) << status.message();
  std::printf("dense orbit: sequential matching registered %d of 60, round keyframes %d (%s)\n",
              summary.sequential_registered, summary.registered, summary.reason.c_str());
  EXPECT_GE(summary.sequential_registered, 0);
  EXPECT_LT(summary.sequential_registered, 54);
  EXPECT_EQ(summary.keyframe_step, 3);
  EXPECT_NE(summary.reason.find("20 keyframes (one image in 3) were mapped and the rest registered"),
            std::string::npos)
      << summary.reason;
  // Measured: 58 of 60 (the two left had too few matches with their one neighbour).
  EXPECT_GE(summary.registered, 54);
  CameraErrors errors;
  ASSERT_TRUE(EvaluateWorldCameras(cameras, capture, truth, nullptr, &errors).ok());
  std::printf("dense orbit: rotation %.3f deg, centre %.2f mm (median), max %.3f deg %.2f mm\n",
              errors.median_rotation_deg, errors.median_centre_mm, errors.max_rotation_deg, errors.max_centre_mm);
  EXPECT_LT(errors.median_rotation_deg, 0.5);
  EXPECT_LT(errors.median_centre_mm, 10.0);
}

// The first `frames` frames of the GRID clip lbax4n ingested into dir/workspace.
void IngestGridClip(const fs::path& dir, int frames, IngestedCapture* capture) {
  IngestOptions ingest;
  ingest.inputs = {(kData / "video" / "grid" / "lbax4n.mpg").string()};
  ingest.max_frames = frames;
  ResolveIngestDefaults(DefaultDataDir(), &ingest);
  NullProgress progress;
  IngestSummary summary;
  ASSERT_TRUE(RunIngest(ingest, dir / "workspace", 2, &progress, &summary).ok());
  ASSERT_TRUE(ReadIngestedCapture(dir / "workspace", capture).ok());
}

TEST(Calibrate, HeadPoseCamerasOnAGridClipReprojectTheLandmarks) {
  const fs::path dir = Scratch("grid");
  IngestedCapture capture;
  ASSERT_NO_FATAL_FAILURE(IngestGridClip(dir, 40, &capture));
  NullProgress progress;
  CalibrateOptions options;  // auto: a still background means a fixed camera
  CameraSet cameras;
  CalibrateSummary result;
  const Status status = RunCalibrate(options, capture, Model(), dir / "out", &progress, &cameras, &result);
  ASSERT_TRUE(status.ok()) << status.message();
  EXPECT_EQ(result.mode, "head-pose");
  EXPECT_NE(result.reason.find("fixed camera"), std::string::npos) << result.reason;
  // Its plain backdrop under compression: few features follow, and the grey
  // levels stay put.
  BackgroundMotion motion;
  ASSERT_TRUE(MeasureBackgroundMotion(capture, capture.cameras[0].name, &motion).ok());
  std::printf("GRID background: %s\n", motion.Describe().c_str());
  EXPECT_LT(motion.change, 3.0);
  EXPECT_FALSE(motion.Moving(1.5));
  std::printf("GRID head-pose: median landmark error %.2f px at 360x288, focal %.0f px\n",
              result.reprojection_source_px, result.focal);
  EXPECT_LT(result.reprojection_source_px, 3.0);
  EXPECT_EQ(cameras.frame, "head");
  ASSERT_EQ(cameras.views.size(), 40u);
  // The camera looks at the face from the front (+z of the head frame).
  EXPECT_GT(cameras.views[0].Centre().z(), 0.2);
  AlignResult aligned;
  ASSERT_TRUE(RunAlign(AlignOptions(), capture, cameras, Model(), &aligned).ok());
  EXPECT_DOUBLE_EQ(aligned.head_from_world.scale, 1.0);
  EXPECT_GT(aligned.median_mm, 0.0);
  EXPECT_LT(aligned.median_mm, 10.0);
}

// A user who knows the lens gives its field of view: the focal length is
// set from it through the crop.
TEST(Calibrate, AKnownFieldOfViewSetsTheFocalLength) {
  const fs::path dir = Scratch("grid_fov");
  IngestedCapture capture;
  ASSERT_NO_FATAL_FAILURE(IngestGridClip(dir, 20, &capture));
  NullProgress progress;
  const IngestedCamera& cam = capture.cameras[0];
  CalibrateOptions options;
  options.mode = "head-pose";
  options.head_pose.fov_deg = 50.0;
  CameraSet cameras;
  CalibrateSummary result;
  ASSERT_TRUE(RunCalibrate(options, capture, Model(), dir / "fov", &progress, &cameras, &result).ok());
  // 50 degrees over the 360 source pixels: 386 px, times the crop's scale.
  const double expected = 180.0 / std::tan(25.0 * 3.14159265358979323846 / 180.0) * cam.crop_scale;
  EXPECT_NEAR(result.focal, expected, 1e-6 * expected);
  EXPECT_NEAR(cameras.cameras[0].fx, expected, 1e-6 * expected);
  EXPECT_LT(result.reprojection_source_px, 4.0);
  options.head_pose.focal = 900;  // both: refused
  EXPECT_FALSE(options.Check().ok());
  options.head_pose.focal = 0;
  options.head_pose.fov_deg = 180;
  EXPECT_FALSE(options.Check().ok());
}

TEST(Calibrate, AutoModeFallsBackToHeadPoseWhenColmapFails) {
  const fs::path dir = Scratch("fallback");
  IngestOptions ingest;
  ingest.inputs = {(kData / "video" / "grid" / "sbwe5n.mpg").string()};
  ingest.max_frames = 12;
  ResolveIngestDefaults(DefaultDataDir(), &ingest);
  NullProgress progress;
  IngestSummary summary;
  ASSERT_TRUE(RunIngest(ingest, dir / "workspace", 2, &progress, &summary).ok());
  IngestedCapture capture;
  ASSERT_TRUE(ReadIngestedCapture(dir / "workspace", &capture).ok());
  CalibrateOptions options;
  options.colmap.executable = DefaultColmapExecutable();
  options.motion_threshold_px = -1.0;  // treat the video as a moving camera: COLMAP runs and fails
  CameraSet cameras;
  CalibrateSummary result;
  ASSERT_TRUE(RunCalibrate(options, capture, Model(), dir / "auto", &progress, &cameras, &result).ok());
  EXPECT_EQ(result.mode, "head-pose");
  EXPECT_NE(result.reason.find("fell back to head-pose"), std::string::npos) << result.reason;
  // Both messages name COLMAP's log, and it is there to read.
  auto named_log = [](const std::string& message) {
    const size_t end = message.find("colmap.log");
    if (end == std::string::npos) return fs::path();
    const size_t start = message.rfind(' ', end) + 1;
    return fs::path(message.substr(start, end + std::strlen("colmap.log") - start));
  };
  EXPECT_TRUE(fs::is_regular_file(named_log(result.reason))) << result.reason;
  // Asked for COLMAP alone, the same frames fail with a message saying what to try.
  options.mode = "colmap";
  const Status failed = RunCalibrate(options, capture, Model(), dir / "colmap", &progress, &cameras, &result);
  ASSERT_FALSE(failed.ok());
  EXPECT_NE(failed.message().find("Try"), std::string::npos) << failed.message();
  EXPECT_TRUE(fs::is_regular_file(named_log(failed.message()))) << failed.message();
}

// Fixed cameras seen at several instants: COLMAP's model must place each
// camera's instants together; a camera in two places means a broken model.
TEST(Calibrate, FixedCamerasMustAgreeAcrossInstants) {
  CameraSet cameras;
  const double radius = 0.9;
  auto view = [&](int camera, int frame, double yaw_deg, const Eigen::Vector3d& shift) {
    CameraView v;
    v.camera = "cam" + std::to_string(camera);
    v.frame = frame;
    v.registered = true;
    const double yaw = yaw_deg * M_PI / 180;
    const Eigen::Vector3d centre = radius * Eigen::Vector3d(std::sin(yaw), 0, std::cos(yaw)) + shift;
    v.cam_from_world.linear() = Eigen::AngleAxisd(-yaw, Eigen::Vector3d::UnitY()).toRotationMatrix();
    v.cam_from_world.translation() = -v.cam_from_world.linear() * centre;
    return v;
  };
  // Four cameras 30 degrees apart on a 0.9 m circle (the median distance between
  // them, the rig's size, is 0.9 m), two instants each.
  for (int c = 0; c < 4; ++c)
    for (int f = 0; f < 2; ++f) cameras.views.push_back(view(c, f, 30.0 * c + 0.2 * f, Eigen::Vector3d(0, 0.002 * f, 0)));
  EXPECT_TRUE(CheckFixedCameraInstants(cameras, 2.0, 0.05).ok());
  CameraSet turned = cameras;
  turned.views[5] = view(2, 1, 60.0 + 5.0, Eigen::Vector3d::Zero());  // cam2 turned by 5 deg (and moved with it)
  const Status s = CheckFixedCameraInstants(turned, 2.0, 0.05);
  EXPECT_EQ(s.code(), Status::Code::kDataError);
  EXPECT_NE(s.message().find("fixed camera cam2"), std::string::npos) << s.message();
  CameraSet moved = cameras;
  moved.views[7] = view(3, 1, 90.0, Eigen::Vector3d(0.1, 0, 0));  // cam3 10 cm away: 11% of the rig's size
  EXPECT_NE(CheckFixedCameraInstants(moved, 2.0, 0.05).message().find("fixed camera cam3"), std::string::npos);
  // An unregistered instant does not count; nor does a camera seen once.
  moved.views[7].registered = false;
  EXPECT_TRUE(CheckFixedCameraInstants(moved, 2.0, 0.05).ok());
}

// A camera circling a scene and coming back past its start: the views at the
// start and the end look the same way but lie far apart in the video, which
// sequential matching never pairs. The model's geometry finds them.
TEST(Calibrate, RevisitPairsCloseTheLoopOfAnOrbit) {
  ColmapTextModel model;
  CameraIntrinsics in;
  in.width = in.height = 320;
  in.fx = in.fy = 400;
  in.cx = in.cy = 159.5;
  model.cameras[1] = in;
  std::map<long, Eigen::Vector3d> points;
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> cube(-0.15, 0.15);
  for (long id = 0; id < 400; ++id) points[id] = Eigen::Vector3d(cube(rng), cube(rng), cube(rng));
  // 26 frames 15 deg apart on a 0.8 m circle looking at the middle: 375 deg,
  // so frames 24 and 25 come back over frames 0 and 1.
  auto add_orbit = [&](int frames, double step_deg) {
    model.images.clear();
    model.observed.clear();
    for (int f = 0; f < frames; ++f) {
      const double yaw = f * step_deg * M_PI / 180;
      const Eigen::Vector3d centre = 0.8 * Eigen::Vector3d(std::sin(yaw), 0, std::cos(yaw));
      Eigen::Isometry3d cam_from_world = Eigen::Isometry3d::Identity();
      // Looking at the origin: the camera's +z points from its centre to the middle.
      cam_from_world.linear() = Eigen::AngleAxisd(yaw + M_PI, Eigen::Vector3d::UnitY()).toRotationMatrix().transpose();
      cam_from_world.translation() = -cam_from_world.linear() * centre;
      const std::string name = "cam0/" + FrameFileName(f);
      model.images[name] = {1, cam_from_world};
      for (const auto& [id, p] : points) {
        const Eigen::Vector3d x = cam_from_world * p;
        // Each view observes the points on its side of the middle.
        if (x.z() > 0 && x.z() < 0.8) model.observed[name].push_back(id);
      }
    }
  };
  add_orbit(26, 15.0);
  // The optical axis of frame 0 points at the middle from +z.
  EXPECT_NEAR((model.images.at("cam0/" + FrameFileName(0)).second * Eigen::Vector3d::Zero()).z(), 0.8, 1e-9);
  std::vector<std::string> order;
  for (const auto& [n, image] : model.images) order.push_back(n);
  auto pairs = FindRevisitPairs(model, points, order, 25.0, 10, 8);
  std::set<std::pair<std::string, std::string>> found(pairs.begin(), pairs.end());
  auto name = [](int f) { return "cam0/" + FrameFileName(f); };
  // Within 25 deg and more than 10 frames apart.
  const std::set<std::pair<std::string, std::string>> expected = {
      {name(0), name(23)}, {name(0), name(24)}, {name(0), name(25)},
      {name(1), name(24)}, {name(1), name(25)}, {name(2), name(25)}};
  EXPECT_EQ(found, expected);
  // One partner per image, the nearest in direction: 0-25 and 1-24 go, since
  // each of their four images has a partner straight ahead.
  pairs = FindRevisitPairs(model, points, order, 25.0, 10, 1);
  found = {pairs.begin(), pairs.end()};
  const std::set<std::pair<std::string, std::string>> nearest = {
      {name(0), name(23)}, {name(0), name(24)}, {name(1), name(25)}, {name(2), name(25)}};
  EXPECT_EQ(found, nearest);
  // Half an orbit never comes back: nothing to match.
  add_orbit(13, 15.0);
  EXPECT_TRUE(FindRevisitPairs(model, points, order, 25.0, 10, 8).empty());
  // Views looking the same way but at other points (most of what one sees is outside the other's frame) are no pair.
  add_orbit(26, 15.0);
  for (auto& [n, image] : model.images)
    if (n == name(24)) image.second.translation() += Eigen::Vector3d(2.0, 0, 0);
  pairs = FindRevisitPairs(model, points, order, 25.0, 10, 8);
  for (const auto& [a, b] : pairs) EXPECT_TRUE(a != name(24) && b != name(24)) << a << " " << b;
}

TEST(Calibrate, RigFilesAreImportedThroughTheCrop) {
  const fs::path dir = Scratch("rig");
  IngestOptions ingest;
  ingest.inputs = {(kData / "video" / "grid" / "bbaf2n.mpg").string()};
  ingest.max_frames = 3;
  ResolveIngestDefaults(DefaultDataDir(), &ingest);
  NullProgress progress;
  IngestSummary summary;
  ASSERT_TRUE(RunIngest(ingest, dir / "workspace", 2, &progress, &summary).ok());
  IngestedCapture capture;
  ASSERT_TRUE(ReadIngestedCapture(dir / "workspace", &capture).ok());
  const nlohmann::json rig = {{"cameras",
                               {{{"name", "cam0"}, {"width", 360}, {"height", 288}, {"fx", 600.0}, {"cx", 179.5},
                                 {"cy", 143.5}, {"cam_from_world", {{1, 0, 0, 0.1}, {0, 1, 0, 0}, {0, 0, 1, 0.7}, {0, 0, 0, 1}}}}}}};
  ASSERT_TRUE(WriteJsonAtomic(dir / "rig.json", rig).ok());
  CalibrateOptions options;
  options.mode = "rig";
  options.rig = (dir / "rig.json").string();
  CameraSet cameras;
  CalibrateSummary result;
  ASSERT_TRUE(RunCalibrate(options, capture, Model(), dir / "out", &progress, &cameras, &result).ok());
  const IngestedCamera& cam = capture.cameras[0];
  const CameraIntrinsics& in = cameras.cameras[0];
  EXPECT_NEAR(in.fx, 600.0 * cam.crop_scale, 1e-9);
  EXPECT_NEAR(in.cx, (179.5 + 0.5 - cam.crop_x0) * cam.crop_scale - 0.5, 1e-9);
  EXPECT_EQ(cameras.registered(), 3);
  EXPECT_NEAR(cameras.views[2].cam_from_world.translation().z(), 0.7, 1e-12);
  EXPECT_EQ(cameras.metres_per_unit, 0.0);  // the file does not say its unit
  // A rig file that says its unit (millimetres) carries it into cameras.json;
  // a negative unit is refused.
  nlohmann::json millimetres = rig;
  millimetres["metres_per_unit"] = 0.001;
  ASSERT_TRUE(WriteJsonAtomic(dir / "rig_mm.json", millimetres).ok());
  options.rig = (dir / "rig_mm.json").string();
  CameraSet metric;
  ASSERT_TRUE(RunCalibrate(options, capture, Model(), dir / "out_mm", &progress, &metric, &result).ok());
  EXPECT_EQ(metric.metres_per_unit, 0.001);
  ASSERT_TRUE(metric.Write(dir / "cameras_mm.json").ok());
  CameraSet read_back;
  ASSERT_TRUE(CameraSet::Read(dir / "cameras_mm.json", &read_back).ok());
  EXPECT_EQ(read_back.metres_per_unit, 0.001);
  millimetres["metres_per_unit"] = -1;
  ASSERT_TRUE(WriteJsonAtomic(dir / "rig_negative.json", millimetres).ok());
  options.rig = (dir / "rig_negative.json").string();
  const Status negative = RunCalibrate(options, capture, Model(), dir / "out_negative", &progress, &metric, &result);
  EXPECT_EQ(negative.code(), Status::Code::kDataError);
  EXPECT_NE(negative.message().find("metres_per_unit must be a positive number"), std::string::npos)
      << negative.message();
  // The same rig as a COLMAP text model folder (pixel centres at +0.5 there).
  fs::create_directories(dir / "colmap_rig");
  ASSERT_TRUE(WriteFileAtomic(dir / "colmap_rig" / "cameras.txt", "# comment\n1 PINHOLE 360 288 600 600 180 144\n").ok());
  ASSERT_TRUE(WriteFileAtomic(dir / "colmap_rig" / "images.txt", "1 1 0 0 0 0.1 0 0.7 1 cam0/000000.png\n\n").ok());
  options.rig = (dir / "colmap_rig").string();
  CameraSet from_colmap;
  ASSERT_TRUE(RunCalibrate(options, capture, Model(), dir / "out2", &progress, &from_colmap, &result).ok());
  EXPECT_NEAR(from_colmap.cameras[0].cx, in.cx, 1e-9);
  EXPECT_NEAR(from_colmap.cameras[0].fx, in.fx, 1e-9);
  EXPECT_NEAR(from_colmap.views[1].cam_from_world.translation().x(), 0.1, 1e-12);
  // The folder may hold a camera at several instants, if they agree: another
  // image of cam0 a millimetre away is accepted, one turned by 5 deg is not, nor
  // one through another lens.
  ASSERT_TRUE(WriteFileAtomic(dir / "colmap_rig" / "images.txt",
                              "1 1 0 0 0 0.1 0 0.7 1 cam0/000000.png\n\n"
                              "2 1 0 0 0 0.101 0 0.7 1 cam0/000001.png\n\n").ok());
  ASSERT_TRUE(RunCalibrate(options, capture, Model(), dir / "out3", &progress, &from_colmap, &result).ok());
  const double half = 2.5 * M_PI / 180;  // quaternion of a 5 deg turn about y
  ASSERT_TRUE(WriteFileAtomic(dir / "colmap_rig" / "images.txt",
                              "1 1 0 0 0 0.1 0 0.7 1 cam0/000000.png\n\n2 " + std::to_string(std::cos(half)) +
                                  " 0 " + std::to_string(std::sin(half)) + " 0 0.1 0 0.7 1 cam0/000001.png\n\n").ok());
  Status turned = RunCalibrate(options, capture, Model(), dir / "out4", &progress, &from_colmap, &result);
  EXPECT_EQ(turned.code(), Status::Code::kDataError);
  EXPECT_NE(turned.message().find("fixed camera cam0 lies at two instants 5.0 deg"), std::string::npos) << turned.message();
  ASSERT_TRUE(WriteFileAtomic(dir / "colmap_rig" / "cameras.txt",
                              "1 PINHOLE 360 288 600 600 180 144\n2 PINHOLE 360 288 640 640 180 144\n").ok());
  ASSERT_TRUE(WriteFileAtomic(dir / "colmap_rig" / "images.txt",
                              "1 1 0 0 0 0.1 0 0.7 1 cam0/000000.png\n\n2 1 0 0 0 0.1 0 0.7 2 cam0/000001.png\n\n").ok());
  turned = RunCalibrate(options, capture, Model(), dir / "out5", &progress, &from_colmap, &result);
  EXPECT_EQ(turned.code(), Status::Code::kDataError);
  EXPECT_NE(turned.message().find("camera cam0 have different intrinsics"), std::string::npos) << turned.message();
  // A rig file for another camera size is refused.
  ASSERT_TRUE(WriteJsonAtomic(dir / "bad.json", nlohmann::json{{"cameras", {{{"name", "cam0"}, {"width", 640}, {"height", 480}, {"fx", 1.0}, {"cx", 1.0}, {"cy", 1.0}, {"cam_from_world", {{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}, {0, 0, 0, 1}}}}}}}).ok());
  options.rig = (dir / "bad.json").string();
  const Status bad = RunCalibrate(options, capture, Model(), dir / "bad", &progress, &cameras, &result);
  EXPECT_FALSE(bad.ok());
  EXPECT_NE(bad.message().find("640x480"), std::string::npos) << bad.message();
}

}  // namespace
}  // namespace headforge
