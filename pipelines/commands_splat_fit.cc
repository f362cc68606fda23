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
#include "core/stage.h"
#include "core/stats_log.h"
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


// The fit as a stage of its own, its --out folder a workspace: skipped when
// up to date, and resumed from its checkpoint after an interruption (the
// pattern of every long stage).
class SplatFitJob : public StageJob {
 public:
  void AddOptions(OptionSet* options) override;
  Status Check() const override;
  Status AddInputs(Hasher* hasher) const override { return hasher->AddFileContents(scene_path_); }
  Status Run(const StageEnv& env, const StageContext& context, StageResult* result) override;
  const std::string& out_dir() const { return out_dir_; }

 private:
  // The scene's views at the fitting resolution, split into training and held-out ones.
  Status RenderViews(const StageEnv& env, std::vector<SplatFitView>* train, std::vector<SplatFitView>* test,
                     SplatFitPoints* init, std::string* scene_name, cv::Size* size);

  std::string scene_path_, out_dir_;
  int resolution_ = 256, holdout_every_ = 8, frames_ = 0, init_points_ = 60000, init_views_ = 0, seed_ = 0;
  SplatFitOptions fit_;
};

void SplatFitJob::AddOptions(OptionSet* options) {
  // Defaults sized for a 256-pixel orbit on a 2-core CPU within 15 minutes.
  fit_.iterations = 8000;
  fit_.max_minutes = 15;
  fit_.densify.stop = 5000;
  fit_.densify.grad_threshold = 0.0003;
  fit_.densify.max_gaussians = 400000;
  options->Add("splat_fit.scene", &scene_path_, "Scene file (TOML) whose frames and ground-truth cameras are fitted.", "scene");
  options->Add("splat_fit.out", &out_dir_,
               "Output folder (a workspace): stats.jsonl, report.json, gaussians.ply, held-out renders.", "out",
               OptionSet::Effect::kRuntime);
  options->Add("splat_fit.resolution", &resolution_, "Image width in pixels (height follows the scene's aspect).", "resolution");
  options->Add("splat_fit.frames", &frames_, "Use only the first N frames of the scene (0: all).", "frames");
  options->Add("splat_fit.holdout_every", &holdout_every_, "Every Nth frame is held out for evaluation.", "holdout-every");
  options->Add("splat_fit.iterations", &fit_.iterations, "Optimisation steps (one view each).", "iterations");
  options->Add("splat_fit.max_minutes", &fit_.max_minutes, "Stop after this many minutes of fitting (0: no limit).", "max-minutes");
  options->Add("splat_fit.init_points", &init_points_,
               "Starting Gaussians, back-projected from the simulator's depth at random pixels of training views.",
               "init-points");
  options->Add("splat_fit.init_views", &init_views_, "How many training views give starting points (0: all).",
               "init-views");
  options->Add("splat_fit.ssim_weight", &fit_.ssim_weight, "Loss = (1 - w) L1 + w (1 - SSIM).", "ssim-weight");
  options->Add("splat_fit.lr_means", &fit_.lr_means, "Adam step for the means (times the scene extent), decaying to 1%.", "lr-means");
  options->Add("splat_fit.lr_scales", &fit_.lr_scales, "Adam step for the log-scales.", "lr-scales");
  options->Add("splat_fit.lr_opacity", &fit_.lr_opacity, "Adam step for the opacity logits.", "lr-opacity");
  options->Add("splat_fit.lr_colours", &fit_.lr_colours, "Adam step for the colour logits.", "lr-colours");
  options->Add("splat_fit.densify_until", &fit_.densify.stop, "Last step that densifies or resets opacities.", "densify-until");
  options->Add("splat_fit.densify_every", &fit_.densify.interval, "Steps between densifications.", "densify-every");
  options->Add("splat_fit.grad_threshold", &fit_.densify.grad_threshold,
               "Mean screen-space gradient above which a Gaussian is cloned or split.", "grad-threshold");
  options->Add("splat_fit.max_gaussians", &fit_.densify.max_gaussians, "Densification stops adding beyond this count.", "max-gaussians");
  options->Add("splat_fit.log_every", &fit_.log_every, "Steps between lines of stats.jsonl.", "log-every");
  options->Add("splat_fit.eval_every", &fit_.eval_every, "Steps between held-out evaluations (0: only at the end).", "eval-every");
  options->Add("splat_fit.checkpoint_every", &fit_.checkpoint_every,
               "Steps between checkpoints; an interrupted fit (Ctrl-C, a kill) run again resumes from the last.",
               "checkpoint-every", OptionSet::Effect::kRuntime);
  options->Add("splat_fit.device", &fit_.device,
               "Where the fit runs: cpu, or cuda (cuda:N) in a build against a LibTorch with CUDA.", "device");
  options->Add("splat_fit.seed", &seed_, "Seed for the view order, starting points and splits.", "seed");
}

Status SplatFitJob::Check() const {
  if (scene_path_.empty()) return Status::InvalidArgument("give the scene file with --scene");
  if (out_dir_.empty()) return Status::InvalidArgument("give the output folder with --out");
  if (resolution_ < 16) return Status::InvalidArgument("--resolution must be at least 16");
  if (holdout_every_ < 2) return Status::InvalidArgument("--holdout-every must be at least 2");
  if (init_points_ < 1 || init_views_ < 0)
    return Status::InvalidArgument("--init-points must be positive and --init-views >= 0");
  std::string why;
  if (!fit_.Check(&why)) return Status::InvalidArgument("splat-fit: " + why);
  // Before the scene is rendered: a device that cannot run the fit fails now.
  return CheckSplatFitDevice(fit_.device);
}

Status SplatFitJob::RenderViews(const StageEnv& env, std::vector<SplatFitView>* train,
                                std::vector<SplatFitView>* test, SplatFitPoints* init, std::string* scene_name,
                                cv::Size* size) {
  std::string text;
  HF_RETURN_IF_ERROR(ReadFileToString(scene_path_, &text).WithContext("scene"));
  Scene scene;
  HF_RETURN_IF_ERROR(ParseScene(text, scene_path_, &scene));
  *scene_name = scene.name;
  // Render at the fitting resolution: the same cameras with fewer pixels.
  SceneIntrinsics& in = scene.camera.intrinsics;
  const double factor = double(in.width) / resolution_;
  const double fx = in.fx();
  const double cx = in.cx_or_centre(), cy = in.cy_or_centre();
  in.focal = fx / factor;
  in.cx = (cx + 0.5) / factor - 0.5;
  in.cy = (cy + 0.5) / factor - 0.5;
  in.width = resolution_;
  in.height = static_cast<int>(std::lround(in.height / factor));
  *size = cv::Size(in.width, in.height);
  FaceModel model;
  HF_RETURN_IF_ERROR(FaceModel::Load(env.settings->face_model, &model));
  std::unique_ptr<Simulator> simulator;
  HF_RETURN_IF_ERROR(Simulator::Create(scene, model, env.settings->threads, &simulator));
  const int num_frames = frames_ > 0 ? std::min(frames_, simulator->num_frames()) : simulator->num_frames();
  std::vector<DepthSource> init_sources;
  env.progress->Start("rendering views", int64_t(num_frames) * simulator->num_cameras());
  for (int f = 0; f < num_frames; ++f) {
    for (int c = 0; c < simulator->num_cameras(); ++c) {
      SimulatedView view = simulator->RenderView(f, c);
      SplatFitView posed{view.image.clone(), view.camera, simulator->CameraName(c) + "_" + std::to_string(f)};
      const bool held_out = f % holdout_every_ == holdout_every_ / 2;
      (held_out ? *test : *train).push_back(posed);
      if (!held_out) init_sources.push_back({view.render.depth, view.image, view.camera});
      env.progress->Advance();
    }
  }
  env.progress->Finish(std::to_string(train->size()) + " training and " + std::to_string(test->size()) +
                       " held-out views at " + std::to_string(in.width) + "x" + std::to_string(in.height));
  // Starting points from evenly spread training views.
  std::mt19937_64 rng(fit_.seed + 2);
  const int sources = init_views_ > 0 ? std::min<int>(init_views_, int(init_sources.size())) : int(init_sources.size());
  for (int i = 0; i < sources; ++i) {
    const DepthSource& v = init_sources[size_t(i) * init_sources.size() / sources];
    AddDepthPoints(v, init_points_ / sources, rng, init);
  }
  // The extent of the cameras (as in 3D Gaussian Splatting): how far they sit
  // from their centroid, which scales position steps and the clone/split size.
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const auto& v : init_sources) centroid += v.camera.Centre() / double(init_sources.size());
  double extent = 0;
  for (const auto& v : init_sources) extent = std::max(extent, (v.camera.Centre() - centroid).norm());
  fit_.densify.scene_extent = 1.1 * std::max(extent, 0.1);
  HF_LOG(Info) << "splat-fit: " << init->sizes.size() << " starting Gaussians, scene extent "
               << fit_.densify.scene_extent << " m";
  return Status::Ok();
}

Status SplatFitJob::Run(const StageEnv& env, const StageContext& context, StageResult* result) {
  fit_.seed = static_cast<uint64_t>(seed_);
  fit_.densify.seed = static_cast<uint64_t>(seed_) + 1;
  fit_.checkpoint_path = (context.staging / "checkpoint.pt").string();
  std::vector<SplatFitView> train, test;
  SplatFitPoints init;
  std::string scene_name;
  cv::Size size;
  HF_RETURN_IF_ERROR(RenderViews(env, &train, &test, &init, &scene_name, &size));
  // Lines written after the last checkpoint (or with none) are dropped by the fit.
  const fs::path stats_path = context.staging / "stats.jsonl";
  if (!fs::exists(fit_.checkpoint_path)) HF_RETURN_IF_ERROR(RemoveAll(stats_path));
  StatsLog stats;
  HF_RETURN_IF_ERROR(StatsLog::Open(stats_path, &stats));
  SplatFitOutput fitted;
  HF_RETURN_IF_ERROR(RunSplatFit(fit_, train, test, init, &stats, env.progress, &fitted));
  HF_RETURN_IF_ERROR(WriteGaussianPly(context.staging / "gaussians.ply", ToCloud(fitted)));
  HF_RETURN_IF_ERROR(EnsureDirectory(context.staging / "held_out"));
  nlohmann::json views = nlohmann::json::array();
  for (size_t i = 0; i < test.size(); ++i) {
    cv::Mat side;
    cv::hconcat(fitted.test_renders[i], test[i].image, side);
    HF_RETURN_IF_ERROR(WriteImageAtomic(context.staging / "held_out" / (test[i].name + ".png"), side));
    views.push_back({{"view", test[i].name}, {"psnr", fitted.view_psnr[i]}});
  }
  const nlohmann::json report = {{"scene", scene_name},
                                 {"width", size.width},
                                 {"height", size.height},
                                 {"train_views", train.size()},
                                 {"test_views", test.size()},
                                 {"steps", fitted.steps},
                                 {"resumed_from", fitted.resumed_from},
                                 {"gaussians", fitted.size},
                                 {"fit_seconds", fitted.seconds},
                                 {"threads", env.settings->threads},
                                 {"device", fit_.device},
                                 {"test_psnr", fitted.test_psnr},
                                 {"test_ssim", fitted.test_ssim},
                                 {"views", views}};
  HF_RETURN_IF_ERROR(WriteFileAtomic(context.staging / "report.json", report.dump(2) + "\n"));
  result->outputs = {"stats.jsonl", "report.json", "gaussians.ply", "held_out"};
  char text[200];
  std::snprintf(text, sizeof(text), "%d steps in %d s, %lld Gaussians; held-out PSNR %.2f dB, SSIM %.3f (%zu views)",
                fitted.steps, int(fitted.seconds), static_cast<long long>(fitted.size), fitted.test_psnr,
                fitted.test_ssim, test.size());
  result->message = text;
  return Status::Ok();
}

}  // namespace

int SplatFitCommand(const std::vector<std::string>& args) {
  StageEntry entry;
  entry.name = "splat_fit";
  entry.uses_face_model = true;
  entry.resumable = true;
  OptionSet options;
  CommonOptions common;
  AddCommonOptions(&options, &common, /*with_workspace=*/false);
  SplatFitJob job;
  job.AddOptions(&options);
  const int parsed = ParseOrExit(&options, args, "headforge splat-fit --scene FILE --out DIR [options]",
                                 "Fits a static Gaussian scene to a simulated capture with ground-truth cameras\n"
                                 "(L1 + SSIM, Adam, densify and prune) and reports PSNR and SSIM on held-out views.\n"
                                 "The output folder is a workspace: a second run with the same options is skipped,\n"
                                 "and a fit interrupted (Ctrl-C, a kill) continues from its last checkpoint.\n"
                                 "Example: headforge splat-fit --scene scenes/orbit_360.toml --out /tmp/fit");
  if (parsed >= 0) return parsed;
  if (Status s = common.Check(false); !s.ok()) return ReportFailure(s);
  if (Status s = job.Check(); !s.ok()) return ReportFailure(s);
  ApplyCommonOptions(common);
  std::unique_ptr<Workspace> workspace;
  if (Status s = Workspace::Open(job.out_dir(), Workspace::Mode::kReadWrite, &workspace); !s.ok())
    return ReportFailure(s);
  StderrProgress progress;
  bool skipped = false;
  if (Status s = RunStageJob(entry, &job, options, workspace.get(), common.Settings(), &progress, false, &skipped);
      !s.ok())
    return ReportFailure(s);
  HF_LOG(Info) << "splat-fit: wrote " << job.out_dir() << (skipped ? " (up to date: nothing to redo)" : "");
  return kExitOk;
}

}  // namespace headforge
