#include "reconstruction/tracker.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>

#include "calibration/mesh_embedding.h"
#include "calibration/reprojection_cost.h"
#include "core/statistics.h"

namespace headforge {
namespace {

struct FrameBlocks {
  double rotation[3] = {0, 0, 0};
  double translation[3] = {0, 0, 0};
  std::vector<double> expression;
  bool observed = false;
};

Eigen::Isometry3d MotionOf(const FrameBlocks& b) {
  Eigen::Isometry3d m = Eigen::Isometry3d::Identity();
  const Eigen::Vector3d aa(b.rotation[0], b.rotation[1], b.rotation[2]);
  if (aa.norm() > 0) m.linear() = Eigen::AngleAxisd(aa.norm(), aa.normalized()).toRotationMatrix();
  m.translation() = Eigen::Vector3d(b.translation[0], b.translation[1], b.translation[2]);
  return m;
}

// Whether landmark i of a view enters the fit.
bool Usable(const TrackingView& view, int i) {
  const double confidence = view.confidence.empty() ? 1.0 : view.confidence[i];
  return confidence > 0 && (*view.landmarks)[i].allFinite();
}

// Pixel distances between a view's usable landmarks and the model's, with
// the indices they belong to.
std::vector<double> ViewResiduals(const TrackingView& view, const LandmarkBasis& basis,
                                  const Eigen::VectorXd& alpha, const FrameBlocks& frame, double focal_scale,
                                  std::vector<int>* indices = nullptr) {
  const TrackingCamera camera = view.camera.WithFocalScale(focal_scale);
  const Eigen::Isometry3d motion = MotionOf(frame);
  const Eigen::VectorXd beta = Eigen::Map<const Eigen::VectorXd>(frame.expression.data(), frame.expression.size());
  std::vector<double> r;
  for (int i = 0; i < 68; ++i) {
    if (!Usable(view, i)) continue;
    r.push_back((camera.Pixel(motion * basis.Point(i, alpha, beta)) - (*view.landmarks)[i]).norm());
    if (indices) indices->push_back(i);
  }
  return r;
}

ceres::LinearSolverType PickLinearSolver() {
  for (auto library : {ceres::SUITE_SPARSE, ceres::EIGEN_SPARSE, ceres::ACCELERATE_SPARSE}) {
    if (ceres::IsSparseLinearAlgebraLibraryTypeAvailable(library)) return ceres::SPARSE_NORMAL_CHOLESKY;
  }
  return ceres::ITERATIVE_SCHUR;
}

}  // namespace

bool TrackOptions::Check(std::string* why) const {
  if (identity_modes < 1) {
    *why = "identity_modes must be at least 1";
    return false;
  }
  if (!(identity_prior >= 0 && expression_sparsity >= 0 && sparsity_scale > 0 && rotation_smoothness >= 0 &&
        translation_smoothness >= 0 && expression_smoothness >= 0 && robust_scale_px > 0 && contour_weight >= 0 &&
        contour_max_yaw_deg >= 0 && mesh_weight >= 0)) {
    *why = "weights must be zero or positive (scales positive)";
    return false;
  }
  if (fixed_head && one_head_motion) {
    *why = "one_head_motion moves the head that fixed_head holds: not both";
    return false;
  }
  if (!(max_focal_change > 1)) {
    *why = "max_focal_change must be above 1";
    return false;
  }
  if (fit_focal && fixed_head) {
    *why = "the focal length can be refined only with the head's motion free";
    return false;
  }
  if (max_iterations < 1 || threads < 1) {
    *why = "max_iterations and threads must be at least 1";
    return false;
  }
  return true;
}

double YawFromCamera(const TrackingCamera& camera, const Eigen::Isometry3d& head_motion) {
  const Eigen::Vector3d facing = camera.rotation * head_motion.linear() * Eigen::Vector3d::UnitZ();
  return std::atan2(facing.x(), -facing.z()) * 180.0 / M_PI;
}

namespace {

// One sequence's fit: the problem, its parameter blocks and what each view
// put into it, built and read by the steps below in TrackSequence's order.
struct SequenceFit {
  SequenceFit(const std::vector<TrackingView>& v, int n, const TrackOptions& o) : views(v), num_frames(n), options(o) {}

  const std::vector<TrackingView>& views;
  const int num_frames;
  const TrackOptions& options;
  LandmarkBasis fit_basis;  // the sequence's basis cut to the fitted identity modes
  LandmarkBasis mesh_basis;  // the face mesh's, cut alike; empty: no mesh
  std::vector<std::shared_ptr<const LandmarkBasis>> own_basis;  // a view's own, where it has one
  std::vector<double> identity;
  double focal_scale = 1.0;
  std::vector<FrameBlocks> frames;
  std::vector<bool> used;  // the view's landmarks are in the fit
  std::vector<std::vector<ceres::ResidualBlockId>> view_blocks;
  ceres::Problem problem;
  ceres::Solver::Options solver;
  ceres::Solver::Summary summary;
  int dropped_views = 0;

  FrameBlocks one_motion;   // every frame's head motion with TrackOptions::one_head_motion

  const LandmarkBasis& BasisOf(size_t v) const { return own_basis[v] ? *own_basis[v] : fit_basis; }
  // The head motion's blocks that frame f's residuals use.
  FrameBlocks& MotionBlocks(FrameBlocks& f) { return options.one_head_motion ? one_motion : f; }
  // Frame f's blocks with the head motion its residuals use.
  FrameBlocks Posed(size_t f) const {
    FrameBlocks b = frames[f];
    if (options.one_head_motion) {
      std::copy(one_motion.rotation, one_motion.rotation + 3, b.rotation);
      std::copy(one_motion.translation, one_motion.translation + 3, b.translation);
    }
    return b;
  }
  Eigen::VectorXd Alpha() const { return Eigen::Map<const Eigen::VectorXd>(identity.data(), Eigen::Index(identity.size())); }
};

Status CheckSequence(const LandmarkBasis& basis, int num_frames, const TrackOptions& options) {
  std::string why;
  if (!options.Check(&why)) return Status::InvalidArgument("track: " + why);
  if (basis.size() != 68) return Status::InvalidArgument("track: the landmark basis must hold 68 landmarks");
  if (num_frames < 1) return Status::InvalidArgument("track: no frames");
  if (basis.num_identity < options.identity_modes) {
    return Status::InvalidArgument("track: the landmark basis holds " + std::to_string(basis.num_identity) +
                                   " identity modes, fewer than the " + std::to_string(options.identity_modes) +
                                   " asked for");
  }
  return Status::Ok();
}

// The bases cut to the fitted identity modes: the sequence's, and each
// view's own where it has one (shared as it is when it has no more modes);
// the parameter blocks at their starting values.
Status PrepareBlocks(const LandmarkBasis& basis, const LandmarkBasis* mesh_basis, SequenceFit* fit) {
  const int k = fit->options.identity_modes;
  auto truncated = [k](const LandmarkBasis& b) {
    LandmarkBasis t = b;
    t.num_identity = k;
    for (auto& m : t.identity) m = m.leftCols(k).eval();
    return t;
  };
  fit->fit_basis = truncated(basis);
  if (mesh_basis && fit->options.mesh_weight > 0) {
    if (mesh_basis->size() != kMeshEmbeddingPoints || mesh_basis->num_identity < k ||
        mesh_basis->num_expressions != basis.num_expressions)
      return Status::InvalidArgument("track: the face mesh's basis does not match the landmarks'");
    fit->mesh_basis = truncated(*mesh_basis);
  }
  fit->own_basis.resize(fit->views.size());
  for (size_t v = 0; v < fit->views.size(); ++v) {
    const auto& b = fit->views[v].basis;
    if (!b) continue;
    if (b->size() != 68 || b->num_identity < k || b->num_expressions != basis.num_expressions)
      return Status::InvalidArgument("track: a view's landmark basis does not match the sequence's");
    fit->own_basis[v] = b->num_identity == k ? b : std::make_shared<const LandmarkBasis>(truncated(*b));
  }
  fit->identity.assign(size_t(k), 0.0);
  fit->frames.resize(size_t(fit->num_frames));
  for (auto& f : fit->frames) f.expression.assign(size_t(basis.num_expressions), 0.0);
  fit->used.assign(fit->views.size(), false);
  fit->view_blocks.resize(fit->views.size());
  return Status::Ok();
}

// A robust reprojection residual per point of a view's face mesh, its
// outline at `oval` (the jaw contour's weight for the view) times mesh_weight.
void AddMeshResiduals(SequenceFit* fit, size_t v, double oval) {
  const TrackingView& view = fit->views[v];
  FrameBlocks& f = fit->frames[size_t(view.frame)];
  std::vector<bool> on_oval(view.mesh.size(), false);
  for (int i : MeshOvalPoints()) on_oval[size_t(i)] = true;
  for (size_t i = 0; i < view.mesh.size(); ++i) {
    const double weight = fit->options.mesh_weight * (on_oval[i] ? oval : 1.0);
    if (!(weight > 0) || !view.mesh[i].allFinite()) continue;
    fit->view_blocks[v].push_back(fit->problem.AddResidualBlock(
        LandmarkReprojectionCost::Create(fit->mesh_basis, int(i), view.camera, view.mesh[i], weight),
        new ceres::HuberLoss(fit->options.robust_scale_px), fit->MotionBlocks(f).rotation,
        fit->MotionBlocks(f).translation, fit->identity.data(), f.expression.data(), &fit->focal_scale));
  }
}

// A robust reprojection residual per usable landmark of each view. Frames
// seen nearly frontally by some camera ignore their near-profile views,
// where the detector's landmarks are least reliable; the jaw contour fades
// out towards profile.
Status AddLandmarkResiduals(SequenceFit* fit) {
  const TrackOptions& options = fit->options;
  std::vector<bool> has_frontal(size_t(fit->num_frames), false);
  for (const TrackingView& view : fit->views) {
    if (view.frame >= 0 && view.frame < fit->num_frames && view.landmarks &&
        std::abs(YawFromCamera(view.camera, Eigen::Isometry3d::Identity())) <= options.max_fit_yaw_deg) {
      has_frontal[size_t(view.frame)] = true;
    }
  }
  int observations = 0;
  for (size_t v = 0; v < fit->views.size(); ++v) {
    const TrackingView& view = fit->views[v];
    if (view.frame < 0 || view.frame >= fit->num_frames) {
      return Status::InvalidArgument("track: a view refers to frame " + std::to_string(view.frame) + " of " +
                                     std::to_string(fit->num_frames));
    }
    if (!view.landmarks) continue;
    const double view_yaw = std::abs(YawFromCamera(view.camera, Eigen::Isometry3d::Identity()));
    if (has_frontal[size_t(view.frame)] && view_yaw > options.max_fit_yaw_deg) continue;
    fit->used[v] = true;
    FrameBlocks& f = fit->frames[size_t(view.frame)];
    constexpr double kContourFadeDeg = 10.0;
    const double contour =
        options.contour_weight * std::clamp((options.contour_max_yaw_deg - view_yaw) / kContourFadeDeg, 0.0, 1.0);
    for (int i = 0; i < 68; ++i) {
      if (!Usable(view, i)) continue;
      const Eigen::Vector2d& pixel = (*view.landmarks)[i];
      const double confidence = view.confidence.empty() ? 1.0 : view.confidence[i];
      const double weight = confidence * (i < 17 ? contour : 1.0);
      if (!(weight > 0)) continue;
      fit->view_blocks[v].push_back(fit->problem.AddResidualBlock(
          LandmarkReprojectionCost::Create(fit->BasisOf(v), i, view.camera, pixel, weight),
          new ceres::HuberLoss(options.robust_scale_px), fit->MotionBlocks(f).rotation,
          fit->MotionBlocks(f).translation, fit->identity.data(), f.expression.data(), &fit->focal_scale));
      f.observed = true;
      ++observations;
    }
    if (fit->mesh_basis.size() > 0 && view.mesh.size() == size_t(fit->mesh_basis.size()))
      AddMeshResiduals(fit, v, contour);
  }
  if (observations == 0) {
    return Status::DataError("track: no frame has landmarks; check that ingest found the face (landmarks.json)");
  }
  return Status::Ok();
}

// The focal length's scale: bounded, with its prior, or constant.
void AddFocalLength(SequenceFit* fit) {
  const TrackOptions& options = fit->options;
  if (!options.fit_focal) {
    fit->problem.SetParameterBlockConstant(&fit->focal_scale);
    return;
  }
  fit->problem.SetParameterLowerBound(&fit->focal_scale, 0, 1.0 / options.max_focal_change);
  fit->problem.SetParameterUpperBound(&fit->focal_scale, 0, options.max_focal_change);
  if (options.focal_prior_scale > 0 && options.focal_prior_sigma > 0)
    fit->problem.AddResidualBlock(
        LogPriorCost::Create(options.focal_prior_scale, options.robust_scale_px / options.focal_prior_sigma), nullptr,
        &fit->focal_scale);
}

// Priors, bounds, smoothness between consecutive observed frames.
void AddPriorsAndSmoothness(SequenceFit* fit) {
  const TrackOptions& options = fit->options;
  ceres::Problem& problem = fit->problem;
  const int k = options.identity_modes, e = int(fit->fit_basis.num_expressions);
  problem.AddResidualBlock(CoefficientPriorCost::Create(k, options.identity_prior), nullptr, fit->identity.data());
  const bool sampled = options.samples.size() == size_t(fit->num_frames);
  int previous = -1;
  for (int i = 0; i < fit->num_frames; ++i) {
    FrameBlocks& f = fit->frames[size_t(i)];
    if (!f.observed) continue;
    if (options.expression_sparsity > 0) {
      // soft-L1 of scale a costs about 2 a |w| for |w| >> a; scaled so a weight
      // w costs expression_sparsity * w (squared pixels), quadratic below a.
      const double a = options.sparsity_scale;
      problem.AddResidualBlock(CoefficientPriorCost::Create(e, 1.0),
                               new ceres::ScaledLoss(new ceres::SoftLOneLoss(a), options.expression_sparsity / (2 * a),
                                                     ceres::TAKE_OWNERSHIP),
                               f.expression.data());
    }
    for (int j = 0; j < e; ++j) {
      problem.SetParameterLowerBound(f.expression.data(), j, 0.0);
      problem.SetParameterUpperBound(f.expression.data(), j, 1.0);
    }
    if (options.fixed_head) {
      problem.SetParameterBlockConstant(f.rotation);
      problem.SetParameterBlockConstant(f.translation);
    }
    if (previous >= 0) {
      FrameBlocks& p = fit->frames[size_t(previous)];
      // Gaps in the observed frames, or between the samples they came from,
      // weaken the link in proportion.
      const double gap = sampled ? std::max(1, options.samples[size_t(i)] - options.samples[size_t(previous)])
                                 : i - previous;
      if (!options.fixed_head && !options.one_head_motion &&
          (options.rotation_smoothness > 0 || options.translation_smoothness > 0)) {
        problem.AddResidualBlock(PoseSmoothnessCost::Create(options.rotation_smoothness / gap,
                                                            options.translation_smoothness / gap),
                                 nullptr, p.rotation, p.translation, f.rotation, f.translation);
      }
      if (options.expression_smoothness > 0) {
        problem.AddResidualBlock(CoefficientSmoothnessCost::Create(e, options.expression_smoothness / gap), nullptr,
                                 p.expression.data(), f.expression.data());
      }
    }
    previous = i;
  }
}

// Solves; a view whose landmarks disagree with the others of its frame (a
// detector failure, typically on a turned face) is then dropped, and the fit
// repeated.
Status SolveDroppingOutlierViews(SequenceFit* fit) {
  fit->solver.linear_solver_type = PickLinearSolver();
  fit->solver.max_num_iterations = fit->options.max_iterations;
  fit->solver.num_threads = fit->options.threads;
  fit->solver.function_tolerance = 1e-8;
  ceres::Solve(fit->solver, &fit->problem, &fit->summary);
  if (fit->summary.termination_type != ceres::FAILURE) {
    const std::vector<TrackingView>& views = fit->views;
    std::vector<double> view_median(views.size(), 0.0), all_used;
    const Eigen::VectorXd alpha = fit->Alpha();
    for (size_t v = 0; v < views.size(); ++v) {
      if (!fit->used[v]) continue;
      view_median[v] =
          Median(ViewResiduals(views[v], fit->BasisOf(v), alpha, fit->Posed(size_t(views[v].frame)), fit->focal_scale));
      all_used.push_back(view_median[v]);
    }
    const double limit = std::max(fit->options.flag_residual_px, 3.0 * Median(all_used));
    std::vector<int> inliers(size_t(fit->num_frames), 0);
    for (size_t v = 0; v < views.size(); ++v) inliers[size_t(views[v].frame)] += fit->used[v] && view_median[v] <= limit;
    int dropped = 0;
    for (size_t v = 0; v < views.size(); ++v) {
      if (!fit->used[v] || view_median[v] <= limit || inliers[size_t(views[v].frame)] == 0) continue;
      for (ceres::ResidualBlockId id : fit->view_blocks[v]) fit->problem.RemoveResidualBlock(id);
      fit->used[v] = false;
      ++dropped;
    }
    if (dropped > 0) {
      ceres::Solve(fit->solver, &fit->problem, &fit->summary);
      fit->dropped_views = dropped;
    }
  }
  if (fit->summary.termination_type == ceres::FAILURE || !std::isfinite(fit->summary.final_cost)) {
    return Status::Internal("track: the solver failed: " + fit->summary.message);
  }
  for (double a : fit->identity) {
    if (!std::isfinite(a)) return Status::Internal("track: the identity became non-finite");
  }
  if (!std::isfinite(fit->focal_scale)) return Status::Internal("track: the focal length became non-finite");
  return Status::Ok();
}

// Every frame's motion and expression; for observed frames the median
// residual and the reasons a frame is flagged low-confidence.
void CollectFrames(const SequenceFit& fit, TrackResult* out) {
  const TrackOptions& options = fit.options;
  const int n = fit.num_frames;
  std::vector<std::vector<double>> residuals(static_cast<size_t>(n));
  std::vector<int> seen(static_cast<size_t>(n), 0);
  std::vector<std::string> reasons(static_cast<size_t>(n));
  const Eigen::VectorXd alpha = fit.Alpha();
  for (size_t v = 0; v < fit.views.size(); ++v) {
    const TrackingView& view = fit.views[v];
    if (!fit.used[v]) continue;
    const size_t f = size_t(view.frame);
    std::vector<int> indices;
    const std::vector<double> r = ViewResiduals(view, fit.BasisOf(v), alpha, fit.Posed(f), fit.focal_scale, &indices);
    residuals[f].insert(residuals[f].end(), r.begin(), r.end());
    seen[f] += int(indices.size());
    Eigen::MatrixXd seen_points(2, indices.size());
    for (size_t j = 0; j < indices.size(); ++j) seen_points.col(Eigen::Index(j)) = (*view.landmarks)[indices[j]];
    if (std::abs(YawFromCamera(view.camera, MotionOf(fit.Posed(f)))) > options.max_yaw_deg) {
      reasons[f] += "profile view; ";
    }
    if (seen_points.cols() >= 3) {
      const Eigen::MatrixXd centred = seen_points.colwise() - seen_points.rowwise().mean();
      const Eigen::JacobiSVD<Eigen::MatrixXd> svd(centred);
      const Eigen::Vector2d s = svd.singularValues();
      if (s[1] < 0.1 * s[0]) reasons[f] += "landmarks nearly collinear; ";
    }
  }
  std::vector<double> all;
  const int e = int(fit.fit_basis.num_expressions);
  for (int i = 0; i < n; ++i) {
    const FrameBlocks& blocks = fit.frames[size_t(i)];
    TrackedFrame t;
    t.frame = i;
    t.head_motion = MotionOf(fit.options.one_head_motion ? fit.one_motion : blocks);
    t.expression = Eigen::Map<const Eigen::VectorXd>(blocks.expression.data(), e);
    t.landmarks = seen[size_t(i)];
    if (blocks.observed) {
      t.residual_px = Median(residuals[size_t(i)]);
      all.insert(all.end(), residuals[size_t(i)].begin(), residuals[size_t(i)].end());
      std::string r = reasons[size_t(i)];
      if (t.landmarks < options.min_landmarks) r += "few landmarks; ";
      if (t.residual_px > options.flag_residual_px) r += "high residual; ";
      if (!r.empty()) {
        t.low_confidence = true;
        t.why = r.substr(0, r.size() - 2);
      }
    }
    out->frames.push_back(t);
  }
  out->median_residual_px = Median(all);
}

// Frames without landmarks: linear interpolation between the nearest
// observed frames (constant beyond the ends).
void InterpolateUnobservedFrames(const SequenceFit& fit, TrackResult* out) {
  std::vector<int> observed;
  for (int i = 0; i < fit.num_frames; ++i)
    if (fit.frames[size_t(i)].observed) observed.push_back(i);
  const int e = int(fit.fit_basis.num_expressions);
  for (int i = 0; i < fit.num_frames; ++i) {
    if (fit.frames[size_t(i)].observed) continue;
    const auto next = std::lower_bound(observed.begin(), observed.end(), i);
    const int after = next == observed.end() ? -1 : *next;
    const int before = next == observed.begin() ? -1 : *(next - 1);
    const int a = before >= 0 ? before : after, b = after >= 0 ? after : before;
    const double w = (a == b) ? 0.0 : double(i - a) / double(b - a);
    const FrameBlocks& fa = fit.frames[size_t(a)];
    const FrameBlocks& fb = fit.frames[size_t(b)];
    FrameBlocks mix;
    for (int d = 0; d < 3; ++d) {
      mix.rotation[d] = (1 - w) * fa.rotation[d] + w * fb.rotation[d];
      mix.translation[d] = (1 - w) * fa.translation[d] + w * fb.translation[d];
    }
    TrackedFrame& t = out->frames[size_t(i)];
    t.head_motion = MotionOf(fit.options.one_head_motion ? fit.one_motion : mix);
    t.expression.resize(e);
    for (int j = 0; j < e; ++j) t.expression[j] = (1 - w) * fa.expression[size_t(j)] + w * fb.expression[size_t(j)];
    t.interpolated = true;
    t.low_confidence = true;
    t.why = "no landmarks: interpolated";
  }
}

}  // namespace

Status TrackSequence(const LandmarkBasis& basis, const std::vector<TrackingView>& views, int num_frames,
                     const TrackOptions& options, TrackResult* result, const LandmarkBasis* mesh_basis) {
  HF_RETURN_IF_ERROR(CheckSequence(basis, num_frames, options));
  const auto start = std::chrono::steady_clock::now();
  SequenceFit fit(views, num_frames, options);
  HF_RETURN_IF_ERROR(PrepareBlocks(basis, mesh_basis, &fit));
  HF_RETURN_IF_ERROR(AddLandmarkResiduals(&fit));
  AddFocalLength(&fit);
  AddPriorsAndSmoothness(&fit);
  HF_RETURN_IF_ERROR(SolveDroppingOutlierViews(&fit));

  TrackResult out;
  out.dropped_views = fit.dropped_views;
  out.focal_scale = fit.focal_scale;
  if (options.fit_focal && options.focal_uncertainty)
    out.focal_log_sigma = LogStandardDeviation(&fit.problem, &fit.focal_scale, fit.summary.final_cost);
  out.identity = fit.Alpha();
  out.iterations = static_cast<int>(fit.summary.iterations.size());
  out.solver_report = fit.summary.BriefReport();
  CollectFrames(fit, &out);
  InterpolateUnobservedFrames(fit, &out);
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  *result = std::move(out);
  return Status::Ok();
}

}  // namespace headforge
