// Tracking speed: TrackSequence on synthetic landmark sequences made from the
// ICT model (100 frames; one camera, or three cameras at -30, 0 and 30 degrees per frame), with the
// default options (20 identity modes, 53 blendshapes). Reports frames per
// second of the whole-sequence fit, alone (BM_TrackSequence) and as the track
// stage runs it (BM_TrackStage).
//   build/bench/headforge_track_bench
#include <benchmark/benchmark.h>

#include <random>

#include "calibration/landmark_embedding.h"
#include "core/parallel.h"
#include "core/paths.h"
#include "core/fs.h"
#include "core/progress.h"
#include "reconstruction/track_stage.h"
#include "reconstruction/tracker.h"

namespace headforge {
namespace {

const LandmarkBasis& Basis(const FaceModel** model_out = nullptr) {
  static FaceModel* model = [] {
    auto* m = new FaceModel();
    const Status s = FaceModel::Load(DefaultDataDir() + "/ict_facekit/ict_face_model.h5", m);
    if (!s.ok()) throw std::runtime_error(s.message());
    return m;
  }();
  static LandmarkBasis* basis = [] {
    auto* b = new LandmarkBasis();
    if (!BuildLandmarkBasis(*model, DetectorLandmarkPoints(*model, DefaultLandmarkEmbedding()), 20, b).ok())
      throw std::runtime_error("landmark basis");
    return b;
  }();
  if (model_out) *model_out = model;
  return *basis;
}

TrackingCamera Camera(double yaw_deg) {
  TrackingCamera c;
  c.fx = c.fy = 900;
  c.cx = c.cy = 255.5;
  const Eigen::Matrix3d yaw = Eigen::AngleAxisd(yaw_deg * M_PI / 180, Eigen::Vector3d::UnitY()).toRotationMatrix();
  const Eigen::Matrix3d head_from_cam = yaw * Eigen::Vector3d(1, -1, -1).asDiagonal();
  c.rotation = head_from_cam.transpose();
  c.translation = -c.rotation * (yaw * Eigen::Vector3d(0, 0, 0.6));
  return c;
}

std::vector<TrackingView> Sequence(int frames, const std::vector<double>& yaws) {
  const FaceModel* model = nullptr;
  const LandmarkBasis& basis = Basis(&model);
  std::mt19937 rng(0);
  std::normal_distribution<double> noise(0.0, 0.5);
  Eigen::VectorXd alpha = Eigen::VectorXd::Zero(20);
  for (int k = 0; k < 20; ++k) alpha[k] = 0.5 * noise(rng);
  std::vector<TrackingView> views;
  for (int f = 0; f < frames; ++f) {
    const double s = f / double(frames);
    Eigen::VectorXd beta = Eigen::VectorXd::Zero(basis.num_expressions);
    beta[model->ExpressionIndex("jawOpen")] = 0.5 + 0.5 * std::sin(6 * M_PI * s);
    beta[model->ExpressionIndex("mouthSmile_L")] = 0.3;
    Eigen::Isometry3d motion = Eigen::Isometry3d::Identity();
    motion.linear() = Eigen::AngleAxisd(0.2 * std::sin(2 * M_PI * s), Eigen::Vector3d::UnitY()).toRotationMatrix();
    for (double yaw : yaws) {
      TrackingView v;
      v.frame = f;
      v.camera = Camera(yaw);
      std::array<Eigen::Vector2d, 68> points;
      for (int i = 0; i < 68; ++i) {
        const Eigen::Vector3d p = v.camera.rotation * (motion * basis.Point(i, alpha, beta)) + v.camera.translation;
        points[i] = Eigen::Vector2d(v.camera.fx * p.x() / p.z() + v.camera.cx + noise(rng),
                                    v.camera.fy * p.y() / p.z() + v.camera.cy + noise(rng));
      }
      v.landmarks = points;
      views.push_back(v);
    }
  }
  return views;
}

void BM_TrackSequence(benchmark::State& state) {
  const int frames = 100;
  const int cameras = static_cast<int>(state.range(0));
  const std::vector<double> yaws = cameras == 1 ? std::vector<double>{0.0} : std::vector<double>{-30.0, 0.0, 30.0};
  const auto views = Sequence(frames, yaws);
  TrackOptions options;
  options.threads = HardwareThreads();
  for (auto _ : state) {
    TrackResult result;
    if (!TrackSequence(Basis(), views, frames, options, &result).ok()) state.SkipWithError("tracking failed");
    benchmark::DoNotOptimize(result.median_residual_px);
  }
  state.counters["fps"] = benchmark::Counter(frames, benchmark::Counter::kIsIterationInvariantRate);
  state.SetLabel(std::to_string(frames) + " frames x " + std::to_string(cameras) + " camera(s)");
}
BENCHMARK(BM_TrackSequence)->Arg(1)->Arg(3)->Unit(benchmark::kSecond)->UseRealTime()->Iterations(2);

// The whole `track` stage on the same sequences, as `headforge track` runs it
// (no overlay video): with three cameras 60 degrees apart the views surround
// the head, so each view takes the view grid's points and the fit runs twice.
void BM_TrackStage(benchmark::State& state) {
  const int frames = 100;
  const int cameras = static_cast<int>(state.range(0));
  const std::vector<double> yaws = cameras == 1 ? std::vector<double>{0.0} : std::vector<double>{-30.0, 0.0, 30.0};
  const auto views = Sequence(frames, yaws);
  const FaceModel* model = nullptr;
  Basis(&model);
  IngestedCapture capture;
  CameraSet set;
  set.mode = "colmap";
  set.frame = "head";
  for (int c = 0; c < cameras; ++c) {
    IngestedCamera cam;
    cam.name = "cam" + std::to_string(c);
    cam.width = cam.height = 512;
    capture.cameras.push_back(cam);
    CameraIntrinsics in;
    in.name = cam.name;
    in.model = "PINHOLE";
    in.width = in.height = 512;
    in.fx = in.fy = views[c].camera.fx;
    in.cx = views[c].camera.cx;
    in.cy = views[c].camera.cy;
    set.cameras.push_back(in);
  }
  for (size_t i = 0; i < views.size(); ++i) {  // frame by frame, the cameras in order
    const TrackingView& v = views[i];
    IngestedCamera& cam = capture.cameras[i % cameras];
    IngestedFrame frame;
    frame.index = v.frame;
    Landmarks68 points;
    for (int k = 0; k < 68; ++k) points[k] = cv::Point2f(float((*v.landmarks)[k].x()), float((*v.landmarks)[k].y()));
    frame.landmarks = points;
    cam.frames.push_back(frame);
    CameraView view;
    view.camera = cam.name;
    view.frame = v.frame;
    view.registered = true;
    view.cam_from_world.linear() = v.camera.rotation;
    view.cam_from_world.translation() = v.camera.translation;
    set.views.push_back(view);
  }
  TrackStageOptions options;
  options.overlay = false;
  options.fit.threads = HardwareThreads();
  const fs::path out = fs::temp_directory_path() / "hf_track_bench";
  fs::create_directories(out);
  NullProgress progress;
  TrackSummary summary;
  for (auto _ : state) {
    if (!RunTrack(options, capture, set, *model, out, &progress, &summary).ok()) state.SkipWithError("tracking failed");
    benchmark::DoNotOptimize(summary.median_residual_px);
  }
  state.counters["fps"] = benchmark::Counter(frames, benchmark::Counter::kIsIterationInvariantRate);
  state.SetLabel(std::to_string(frames) + " frames x " + std::to_string(cameras) + " camera(s)");
}
BENCHMARK(BM_TrackStage)->Arg(1)->Arg(3)->Unit(benchmark::kSecond)->UseRealTime()->Iterations(2);

}  // namespace
}  // namespace headforge

BENCHMARK_MAIN();
