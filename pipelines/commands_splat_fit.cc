// `headforge splat-fit`: fits a static Gaussian scene to a simulated capture
// with its ground-truth cameras, and reports held-out PSNR and SSIM.
#include <algorithm>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <random>

#include "avatar/splat_fit_job.h"
#include "capture/simulator.h"
#include "core/image_io.h"
#include "core/log.h"
#include "core/parallel.h"
#include "export/gaussian_ply.h"
#include "pipelines/commands.h"

namespace headforge {
namespace {

// Points back-projected from the simulator's depth at random pixels of a view,
// each sized to the spacing of the samples.
// What a training view gives the initialisation: its depth, colours and camera
// (the simulator's other render buffers are not kept).
struct DepthSource {
  cv::Mat depth, image;
  PinholeCamera camera;
};

void AddDepthPoints(const DepthSource& view, int count, std::mt19937_64& rng, SplatFitPoints* points) {
  const cv::Mat& depth = view.depth;
  const PinholeCamera& cam = view.camera;
  const Eigen::Isometry3d world_from_cam = cam.cam_from_world.inverse();
  const double spacing = std::sqrt(double(depth.rows) * depth.cols / std::max(count, 1));
  const uint64_t pixels = uint64_t(depth.rows) * depth.cols;
  for (int i = 0; i < count; ++i) {
    const uint64_t pick = rng() % pixels;
    const int y = int(pick / depth.cols), x = int(pick % depth.cols);
    const float z = depth.at<float>(y, x);
    if (!(z > 0)) continue;
    const Eigen::Vector3d p = world_from_cam * Eigen::Vector3d((x - cam.cx) / cam.fx * z, (y - cam.cy) / cam.fy * z, z);
    const cv::Vec3b bgr = view.image.at<cv::Vec3b>(y, x);
    points->positions.insert(points->positions.end(), {float(p.x()), float(p.y()), float(p.z())});
    points->colours.insert(points->colours.end(), {bgr[2] / 255.0f, bgr[1] / 255.0f, bgr[0] / 255.0f});
    points->sizes.push_back(float(0.5 * spacing * z / cam.fx));
  }
}

GaussianCloud ToCloud(const SplatFitOutput& fit) {
  GaussianCloud cloud;
  cloud.sh_degree = 0;
  cloud.means = fit.means;
  // Colour = 0.5 + C0 * dc with C0 the degree-0 spherical harmonic, 1 / (2 sqrt(pi)).
  cloud.sh_dc.reserve(fit.colours.size());
  for (float c : fit.colours) cloud.sh_dc.push_back((c - 0.5f) / 0.28209479177387814f);
  cloud.opacities = fit.opacity_logits;
  cloud.log_scales = fit.log_scales;
  cloud.rotations = fit.rotations;
  return cloud;
}

}  // namespace

int SplatFitCommand(const std::vector<std::string>& args) {
  OptionSet options;
  CommonOptions common;
  AddCommonOptions(&options, &common, /*with_workspace=*/false);
  std::string scene_path, out_dir, face_model;
  int resolution = 256, holdout_every = 8, frames = 0, init_points = 60000, init_views = 0;
  SplatFitOptions fit;
  // Defaults sized for a 256-pixel orbit on a 2-core CPU within 15 minutes.
  fit.iterations = 8000;
  fit.max_minutes = 15;
  fit.densify.stop = 5000;
  fit.densify.grad_threshold = 0.0003;
  fit.densify.max_gaussians = 400000;
  options.Add("splat_fit.scene", &scene_path, "Scene file (TOML) whose frames and ground-truth cameras are fitted.", "scene");
  options.Add("splat_fit.out", &out_dir, "Output folder: stats.jsonl, report.json, gaussians.ply, held-out renders.", "out");
  options.Add("splat_fit.resolution", &resolution, "Image width in pixels (height follows the scene's aspect).", "resolution");
  options.Add("splat_fit.frames", &frames, "Use only the first N frames of the scene (0: all).", "frames");
  options.Add("splat_fit.holdout_every", &holdout_every, "Every Nth frame is held out for evaluation.", "holdout-every");
  options.Add("splat_fit.iterations", &fit.iterations, "Optimisation steps (one view each).", "iterations");
  options.Add("splat_fit.max_minutes", &fit.max_minutes, "Stop after this many minutes of fitting (0: no limit).", "max-minutes");
  options.Add("splat_fit.init_points", &init_points,
              "Starting Gaussians, back-projected from the simulator's depth at random pixels of training views.",
              "init-points");
  options.Add("splat_fit.init_views", &init_views, "How many training views give starting points (0: all).",
              "init-views");
  options.Add("splat_fit.ssim_weight", &fit.ssim_weight, "Loss = (1 - w) L1 + w (1 - SSIM).", "ssim-weight");
  options.Add("splat_fit.lr_means", &fit.lr_means, "Adam step for the means (times the scene extent), decaying to 1%.", "lr-means");
  options.Add("splat_fit.lr_scales", &fit.lr_scales, "Adam step for the log-scales.", "lr-scales");
  options.Add("splat_fit.lr_opacity", &fit.lr_opacity, "Adam step for the opacity logits.", "lr-opacity");
  options.Add("splat_fit.lr_colours", &fit.lr_colours, "Adam step for the colour logits.", "lr-colours");
  options.Add("splat_fit.densify_until", &fit.densify.stop, "Last step that densifies or resets opacities.", "densify-until");
  options.Add("splat_fit.densify_every", &fit.densify.interval, "Steps between densifications.", "densify-every");
  options.Add("splat_fit.grad_threshold", &fit.densify.grad_threshold,
              "Mean screen-space gradient above which a Gaussian is cloned or split.", "grad-threshold");
  options.Add("splat_fit.max_gaussians", &fit.densify.max_gaussians, "Densification stops adding beyond this count.", "max-gaussians");
  options.Add("splat_fit.log_every", &fit.log_every, "Steps between lines of stats.jsonl.", "log-every");
  options.Add("splat_fit.eval_every", &fit.eval_every, "Steps between held-out evaluations (0: only at the end).", "eval-every");
  int seed = 0;
  options.Add("splat_fit.device", &fit.device,
              "Where the fit runs: cpu, or cuda (cuda:N) in a build against a LibTorch with CUDA.",
              "device");
  options.Add("splat_fit.seed", &seed, "Seed for the view order, starting points and splits.", "seed");
  options.Add("splat_fit.face_model", &face_model, "Face model; default DATA/ict_facekit/ict_face_model.h5.", "face-model",
              OptionSet::Effect::kRuntime);
  const int parsed = ParseOrExit(&options, args, "headforge splat-fit --scene FILE --out DIR [options]",
                                 "Fits a static Gaussian scene to a simulated capture with ground-truth cameras\n"
                                 "(L1 + SSIM, Adam, densify and prune) and reports PSNR and SSIM on held-out views.\n"
                                 "Example: headforge splat-fit --scene scenes/orbit_360.toml --out /tmp/fit");
  if (parsed >= 0) return parsed;
  if (scene_path.empty()) return ReportFailure(Status::InvalidArgument("give the scene file with --scene"));
  if (out_dir.empty()) return ReportFailure(Status::InvalidArgument("give the output folder with --out"));
  if (resolution < 16) return ReportFailure(Status::InvalidArgument("--resolution must be at least 16"));
  if (holdout_every < 2) return ReportFailure(Status::InvalidArgument("--holdout-every must be at least 2"));
  if (init_points < 1 || init_views < 0) {
    return ReportFailure(Status::InvalidArgument("--init-points must be positive and --init-views >= 0"));
  }
  // Before the scene is rendered: a device that cannot run the fit fails now.
  if (Status s = CheckSplatFitDevice(fit.device); !s.ok()) return ReportFailure(s);
  if (face_model.empty()) face_model = (fs::path(common.data_dir) / "ict_facekit" / "ict_face_model.h5").string();
  ApplyCommonOptions(common);
  fit.seed = static_cast<uint64_t>(seed);
  fit.densify.seed = static_cast<uint64_t>(seed) + 1;

  std::string text;
  if (Status s = ReadFileToString(scene_path, &text).WithContext("scene"); !s.ok()) return ReportFailure(s);
  Scene scene;
  if (Status s = ParseScene(text, scene_path, &scene); !s.ok()) return ReportFailure(s);
  // Render at the fitting resolution: the same cameras with fewer pixels.
  SceneIntrinsics& in = scene.camera.intrinsics;
  const double factor = double(in.width) / resolution;
  const double fx = in.fx();
  const double cx = in.cx_or_centre(), cy = in.cy_or_centre();
  in.focal = fx / factor;
  in.cx = (cx + 0.5) / factor - 0.5;
  in.cy = (cy + 0.5) / factor - 0.5;
  in.width = resolution;
  in.height = static_cast<int>(std::lround(in.height / factor));
  FaceModel model;
  if (Status s = FaceModel::Load(face_model, &model); !s.ok()) return ReportFailure(s);
  std::unique_ptr<Simulator> simulator;
  const int threads = common.threads > 0 ? common.threads : HardwareThreads();
  if (Status s = Simulator::Create(scene, model, threads, &simulator); !s.ok()) return ReportFailure(s);
  const int num_frames = frames > 0 ? std::min(frames, simulator->num_frames()) : simulator->num_frames();

  std::vector<SplatFitView> train, test;
  std::vector<DepthSource> init_sources;
  StderrProgress progress;
  progress.Start("rendering views", int64_t(num_frames) * simulator->num_cameras());
  for (int f = 0; f < num_frames; ++f) {
    for (int c = 0; c < simulator->num_cameras(); ++c) {
      SimulatedView view = simulator->RenderView(f, c);
      SplatFitView posed{view.image.clone(), view.camera, simulator->CameraName(c) + "_" + std::to_string(f)};
      const bool held_out = f % holdout_every == holdout_every / 2;
      (held_out ? test : train).push_back(posed);
      if (!held_out) init_sources.push_back({view.render.depth, view.image, view.camera});
      progress.Advance();
    }
  }
  progress.Finish(std::to_string(train.size()) + " training and " + std::to_string(test.size()) +
                  " held-out views at " + std::to_string(in.width) + "x" + std::to_string(in.height));

  // Starting points from evenly spread training views.
  SplatFitPoints init;
  std::mt19937_64 rng(fit.seed + 2);
  const int sources = init_views > 0 ? std::min<int>(init_views, int(init_sources.size())) : int(init_sources.size());
  for (int i = 0; i < sources; ++i) {
    const DepthSource& v = init_sources[size_t(i) * init_sources.size() / sources];
    AddDepthPoints(v, init_points / sources, rng, &init);
  }
  const size_t n = init.sizes.size();
  // The extent of the cameras (as in 3D Gaussian Splatting): how far they sit
  // from their centroid, which scales position steps and the clone/split size.
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const auto& v : init_sources) centroid += v.camera.Centre() / double(init_sources.size());
  double extent = 0;
  for (const auto& v : init_sources) extent = std::max(extent, (v.camera.Centre() - centroid).norm());
  fit.densify.scene_extent = 1.1 * std::max(extent, 0.1);
  HF_LOG(Info) << "splat-fit: " << n << " starting Gaussians, scene extent " << fit.densify.scene_extent << " m";

  if (Status s = EnsureDirectory(fs::path(out_dir) / "held_out"); !s.ok()) return ReportFailure(s);
  std::ofstream stats_file(fs::path(out_dir) / "stats.jsonl");
  if (!stats_file) return ReportFailure(Status::IoError("cannot write " + (fs::path(out_dir) / "stats.jsonl").string()));
  SplatFitOutput result;
  const Status status = RunSplatFit(fit, train, test, init,
                                  [&](const std::string& line) { stats_file << line << "\n" << std::flush; },
                                  &progress, &result);
  if (!status.ok()) return ReportFailure(status);

  if (Status s = WriteGaussianPly(fs::path(out_dir) / "gaussians.ply", ToCloud(result)); !s.ok()) {
    return ReportFailure(s);
  }
  nlohmann::json views = nlohmann::json::array();
  for (size_t i = 0; i < test.size(); ++i) {
    cv::Mat side;
    cv::hconcat(result.test_renders[i], test[i].image, side);
    if (Status s = WriteImageAtomic(fs::path(out_dir) / "held_out" / (test[i].name + ".png"), side); !s.ok()) {
      return ReportFailure(s);
    }
    views.push_back({{"view", test[i].name}, {"psnr", result.view_psnr[i]}});
  }
  const nlohmann::json report = {{"scene", scene.name},
                                 {"width", in.width},
                                 {"height", in.height},
                                 {"train_views", train.size()},
                                 {"test_views", test.size()},
                                 {"steps", result.steps},
                                 {"gaussians", result.size},
                                 {"fit_seconds", result.seconds},
                                 {"threads", threads},
                                 {"device", fit.device},
                                 {"test_psnr", result.test_psnr},
                                 {"test_ssim", result.test_ssim},
                                 {"views", views}};
  if (Status s = WriteFileAtomic(fs::path(out_dir) / "report.json", report.dump(2) + "\n"); !s.ok()) {
    return ReportFailure(s);
  }
  HF_LOG(Info) << "splat-fit: " << result.steps << " steps in " << int(result.seconds) << " s, "
               << result.size << " Gaussians; held-out PSNR " << result.test_psnr << " dB, SSIM "
               << result.test_ssim << " (" << test.size() << " views); wrote " << out_dir;
  return kExitOk;
}

}  // namespace headforge
