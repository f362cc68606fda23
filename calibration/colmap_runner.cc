#include "calibration/colmap_runner.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdint>
#include <fstream>
#include <map>
#include <set>
#include <opencv2/imgcodecs.hpp>
#include <sstream>

#include "core/image_io.h"
#include "core/log.h"
#include "core/parallel.h"
#include "core/process.h"

namespace headforge {

Status ColmapOptions::Check() const {
  if (camera_model != "SIMPLE_RADIAL" && camera_model != "RADIAL" && camera_model != "OPENCV" &&
      camera_model != "PINHOLE" && camera_model != "SIMPLE_PINHOLE")
    return Status::InvalidArgument("colmap camera model must be SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL or OPENCV");
  if (max_features < 100) return Status::InvalidArgument("colmap max features must be at least 100");
  if (matcher != "auto" && matcher != "sequential" && matcher != "exhaustive")
    return Status::InvalidArgument("colmap matcher must be auto, sequential or exhaustive");
  if (mask != "auto" && mask != "none" && mask != "background" && mask != "head")
    return Status::InvalidArgument("colmap mask must be auto, none, background or head");
  if (frame_step < 1) return Status::InvalidArgument("frame step must be at least 1");
  if (overlap < 1) return Status::InvalidArgument("sequential overlap must be at least 1");
  if (rig_instants < 1) return Status::InvalidArgument("rig instants must be at least 1");
  if (mapper_attempts < 1) return Status::InvalidArgument("mapper attempts must be at least 1");
  if (keyframe_step < 0 || keyframe_step == 1)
    return Status::InvalidArgument("--keyframe-step must be 0 (never) or 2 or more");
  if (exhaustive_fallback_max < 0)
    return Status::InvalidArgument("--exhaustive-fallback must be 0 (never) or more images");
  if (!(revisit_angle_deg >= 0 && revisit_angle_deg < 90))
    return Status::InvalidArgument("--revisit-angle must be 0 (off) or an angle below 90 degrees");
  if (revisit_pairs < 1) return Status::InvalidArgument("--revisit-pairs must be at least 1");
  if (!(max_instant_rotation_deg > 0) || !(max_instant_shift > 0))
    return Status::InvalidArgument("the fixed cameras' instant limits must be positive");
  return Status::Ok();
}

namespace {

// Runs `args` with stdout and stderr appended to `log`; the environment gets
// QT_QPA_PLATFORM=offscreen so no display is needed.
Status RunTool(const std::vector<std::string>& args, const fs::path& log) {
  int exit_code = 0;
  const Status run = RunProgram(args, log, &exit_code, {{"QT_QPA_PLATFORM", "offscreen"}});
  if (run.code() == Status::Code::kNotFound)
    return Status::NotFound("cannot run " + args[0] + " (install Debian's colmap package)");
  HF_RETURN_IF_ERROR(run);
  if (exit_code != 0)
    return Status::DataError("colmap " + args[1] + " failed (exit " + std::to_string(exit_code) + "); see " +
                             log.string());
  return Status::Ok();
}

// The number of registered images in a COLMAP binary images.bin (its first
// eight bytes); 0 when unreadable.
int CountRegisteredImages(const fs::path& images_bin) {
  std::ifstream in(images_bin, std::ios::binary);
  uint64_t count = 0;
  if (!in.read(reinterpret_cast<char*>(&count), sizeof(count))) return 0;
  return static_cast<int>(count);
}

}  // namespace

Status ReadColmapCamerasAndImages(const fs::path& dir, ColmapTextModel* model) {
  std::ifstream cams(dir / "cameras.txt"), images(dir / "images.txt");
  if (!cams || !images) return Status::NotFound("no COLMAP text model (cameras.txt, images.txt) in " + dir.string());
  // cameras.txt: CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]
  std::string line;
  while (std::getline(cams, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream in(line);
    int id;
    CameraIntrinsics c;
    in >> id >> c.model >> c.width >> c.height;
    std::vector<double> p;
    double v;
    while (in >> v) p.push_back(v);
    if (c.model == "SIMPLE_PINHOLE" && p.size() >= 3) {
      c.fx = c.fy = p[0]; c.cx = p[1]; c.cy = p[2];
    } else if (c.model == "PINHOLE" && p.size() >= 4) {
      c.fx = p[0]; c.fy = p[1]; c.cx = p[2]; c.cy = p[3];
    } else if (c.model == "SIMPLE_RADIAL" && p.size() >= 4) {
      c.fx = c.fy = p[0]; c.cx = p[1]; c.cy = p[2]; c.k1 = p[3];
    } else if (c.model == "RADIAL" && p.size() >= 5) {
      c.fx = c.fy = p[0]; c.cx = p[1]; c.cy = p[2]; c.k1 = p[3]; c.k2 = p[4];
    } else if (c.model == "OPENCV" && p.size() >= 8) {
      c.fx = p[0]; c.fy = p[1]; c.cx = p[2]; c.cy = p[3]; c.k1 = p[4]; c.k2 = p[5]; c.p1 = p[6]; c.p2 = p[7];
    } else {
      return Status::DataError("unsupported COLMAP camera model " + c.model + " in " + dir.string());
    }
    // COLMAP puts pixel centres at +0.5; this tool at integers.
    c.cx -= 0.5;
    c.cy -= 0.5;
    model->cameras[id] = c;
  }
  // images.txt: two lines per image; IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME, then its points.
  while (std::getline(images, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream in(line);
    int id, camera_id;
    double qw, qx, qy, qz, tx, ty, tz;
    std::string name;
    in >> id >> qw >> qx >> qy >> qz >> tx >> ty >> tz >> camera_id >> name;
    Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
    t.linear() = Eigen::Quaterniond(qw, qx, qy, qz).normalized().toRotationMatrix();
    t.translation() = Eigen::Vector3d(tx, ty, tz);
    if (!model->cameras.count(camera_id))
      return Status::DataError("COLMAP image " + name + " names an unknown camera " + std::to_string(camera_id));
    model->images[name] = {camera_id, t};
    // POINTS2D[] as (X, Y, POINT3D_ID); -1 for a feature without a point.
    std::getline(images, line);
    std::istringstream obs(line);
    std::vector<long>& ids = model->observed[name];
    double x, y;
    long point;
    while (obs >> x >> y >> point)
      if (point >= 0) ids.push_back(point);
  }
  return Status::Ok();
}

Status ReadColmapPoints(const fs::path& dir, std::map<long, Eigen::Vector3d>* points) {
  std::ifstream in(dir / "points3D.txt");
  if (!in) return Status::NotFound("no points3D.txt in " + dir.string());
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream row(line);
    long id;
    Eigen::Vector3d p;
    if (row >> id >> p.x() >> p.y() >> p.z()) (*points)[id] = p;
  }
  return Status::Ok();
}

std::vector<std::pair<std::string, std::string>> FindRevisitPairs(const ColmapTextModel& model,
                                                                  const std::map<long, Eigen::Vector3d>& points,
                                                                  const std::vector<std::string>& order,
                                                                  double max_angle_deg, int min_index_gap,
                                                                  int per_image) {
  std::vector<std::string> names;  // the images in the model, and their places in `order`
  std::vector<long> place;
  for (size_t k = 0; k < order.size(); ++k)
    if (model.images.count(order[k])) {
      names.push_back(order[k]);
      place.push_back(static_cast<long>(k));
    }
  const double min_cos = std::cos(max_angle_deg * M_PI / 180.0);
  constexpr double kShared = 0.15;
  // Whether at least kShared of what image a observes lies in front of image b
  // and inside its frame (asked both ways for a pair). Low, since a turn of a
  // third of the field of view with parallax on top leaves a third in view;
  // it only keeps out views that look the same way from elsewhere.
  auto overlaps = [&](const std::string& a, const std::string& b) {
    const auto& [camera_b, pose_b] = model.images.at(b);
    const CameraIntrinsics& in = model.cameras.at(camera_b);
    const auto observed = model.observed.find(a);
    if (observed == model.observed.end()) return false;
    int seen = 0, inside = 0;
    for (long id : observed->second) {
      const auto p = points.find(id);
      if (p == points.end()) continue;
      ++seen;
      const Eigen::Vector3d x = pose_b * p->second;
      if (x.z() <= 0) continue;
      const double u = in.fx * x.x() / x.z() + in.cx, v = in.fy * x.y() / x.z() + in.cy;
      inside += u >= -0.5 && v >= -0.5 && u < in.width - 0.5 && v < in.height - 0.5;
    }
    return seen > 0 && inside >= kShared * seen;
  };
  std::set<std::pair<size_t, size_t>> chosen;
  for (size_t i = 0; i < names.size(); ++i) {
    const Eigen::Vector3d axis_i = model.images.at(names[i]).second.linear().row(2).transpose();
    std::vector<std::pair<double, size_t>> partners;  // (-cos, j): nearest in direction first
    for (size_t j = 0; j < names.size(); ++j) {
      if (std::abs(place[i] - place[j]) <= min_index_gap) continue;
      const double cos = axis_i.dot(model.images.at(names[j]).second.linear().row(2).transpose());
      if (cos < min_cos || !overlaps(names[i], names[j]) || !overlaps(names[j], names[i])) continue;
      partners.push_back({-cos, j});
    }
    std::sort(partners.begin(), partners.end());
    for (size_t k = 0; k < partners.size() && static_cast<int>(k) < per_image; ++k)
      chosen.insert({std::min(i, partners[k].second), std::max(i, partners[k].second)});
  }
  std::vector<std::pair<std::string, std::string>> pairs;
  for (const auto& [a, b] : chosen) pairs.push_back({names[a], names[b]});
  return pairs;
}

Status ReadColmapTextModel(const fs::path& dir, const IngestedCapture& capture, CameraSet* cameras,
                           ColmapReport* report) {
  ColmapTextModel model;
  HF_RETURN_IF_ERROR(ReadColmapCamerasAndImages(dir, &model));
  const auto& by_id = model.cameras;
  const auto& posed = model.images;
  std::ifstream points(dir / "points3D.txt");
  std::string line;
  CameraSet set;
  set.mode = "colmap";
  set.frame = "world";
  for (const auto& cam : capture.cameras) {
    bool named = false;
    for (const auto& frame : cam.frames) {
      CameraView view;
      view.camera = cam.name;
      view.frame = frame.index;
      const auto it = posed.find(cam.name + "/" + FrameFileName(frame.index));
      if (it != posed.end()) {
        view.registered = true;
        view.cam_from_world = it->second.second;
        if (!named) {
          CameraIntrinsics c = by_id.at(it->second.first);
          c.name = cam.name;
          set.cameras.push_back(c);
          named = true;
        }
      }
      set.views.push_back(view);
    }
    if (!named) {
      CameraIntrinsics c;
      c.name = cam.name;
      c.width = cam.width;
      c.height = cam.height;
      set.cameras.push_back(c);  // no view registered: intrinsics unknown
    }
  }
  int n_points = 0;
  double error_sum = 0;
  while (points && std::getline(points, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream in(line);
    double id, x, y, z, r, g, b, error;
    in >> id >> x >> y >> z >> r >> g >> b >> error;
    ++n_points;
    error_sum += error;
  }
  report->points = n_points;
  report->mean_reprojection_px = n_points ? error_sum / n_points : 0.0;
  report->registered = set.registered();
  *cameras = std::move(set);
  return Status::Ok();
}

Status CheckFixedCameraInstants(const CameraSet& cameras, double max_rotation_deg, double max_shift) {
  std::map<std::string, std::vector<Eigen::Isometry3d>> instants;
  for (const auto& v : cameras.views)
    if (v.registered) instants[v.camera].push_back(v.cam_from_world);
  std::vector<Eigen::Vector3d> centres;
  for (const auto& [name, poses] : instants) centres.push_back(poses.front().inverse().translation());
  std::vector<double> distances;
  for (size_t a = 0; a < centres.size(); ++a)
    for (size_t b = a + 1; b < centres.size(); ++b) distances.push_back((centres[a] - centres[b]).norm());
  double rig_size = 0;
  if (!distances.empty()) {
    std::nth_element(distances.begin(), distances.begin() + distances.size() / 2, distances.end());
    rig_size = distances[distances.size() / 2];
  }
  std::string worst;
  double worst_excess = 1.0, worst_deg = 0, worst_shift = 0;
  for (const auto& [name, poses] : instants)
    for (size_t i = 1; i < poses.size(); ++i) {
      const double deg =
          Eigen::AngleAxisd(poses[i].linear() * poses.front().linear().transpose()).angle() * 180.0 / M_PI;
      const double shift =
          rig_size > 0 ? (poses[i].inverse().translation() - poses.front().inverse().translation()).norm() / rig_size : 0;
      const double excess = std::max(deg / max_rotation_deg, shift / max_shift);
      if (excess > worst_excess) {
        worst_excess = excess;
        worst = name;
        worst_deg = deg;
        worst_shift = shift;
      }
    }
  if (worst.empty()) return Status::Ok();
  char text[320];
  std::snprintf(text, sizeof(text),
                "fixed camera %s lies at two instants %.1f deg and %.0f%% of the rig's size apart "
                "(limits %.1f deg, %.0f%%)",
                worst.c_str(), worst_deg, 100 * worst_shift, max_rotation_deg, 100 * max_shift);
  return Status::DataError(text);
}

namespace {

// One COLMAP reconstruction of a capture in `work_dir`: the steps RunColmap
// takes, in its order, sharing the database, the log and the report.
class ColmapJob {
 public:
  ColmapJob(const ColmapOptions& options, const IngestedCapture& capture, const fs::path& work_dir,
            ColmapReport* report)
      : options_(options), capture_(capture), work_dir_(work_dir), log_(work_dir / "colmap.log"),
        database_(work_dir / "database.db"), image_path_((capture.workspace / "frames").string()),
        exe_(options.executable), threads_(std::to_string(options.threads > 0 ? options.threads : DefaultThreads())),
        report_(report) {}

  // The frames COLMAP sees, named "<camera>/<index>.png", listed in
  // images.txt: every frame_step-th frame, or for fixed cameras a few
  // synchronised instants; their masks where the mask mode asks for them.
  Status ChooseImages();
  Status ExtractFeatures();
  Status Match(const std::string& matcher);
  // The mapper into sparse/, sparse_1/, ... (numbered on across calls), again
  // with relaxed initialisation while too few images register; keeps the
  // largest model. Fails only when the last attempt fails and nothing was
  // mapped yet.
  Status Map();
  // Sequential matching that registers too few images: keyframes mapped and
  // the rest registered into their model; then, when still too few, every
  // pair matched, and mapped again.
  Status MapWithFallback();
  // Every step-th image mapped, the images between registered: the
  // keyframe fallback's one try.
  Status MapKeyframes(int step);
  // Loop closure: the views the first model shows the camera coming back to
  // are matched, and the model refined with them.
  Status CloseLoops();
  // The best model as text, read into `cameras`.
  Status ReadModel(CameraSet* cameras);
  // Fixed cameras: each one's pose (from its first registered instant) holds
  // for all of its frames, after a check that the instants agree.
  Status HoldFixedCameraPoses(CameraSet* cameras) const;

 private:
  Status Refine(fs::path* refined);
  bool Enough() const { return best_registered_ >= options_.retry_below * total_; }
  // The images in the sequential matcher's order: by name.
  std::vector<std::string> SequentialOrder() const;
  // Of the models under `dir`: the one registering the most images (empty
  // when none), and their number.
  static fs::path LargestModel(const fs::path& dir, int* registered);

  const ColmapOptions& options_;
  const IngestedCapture& capture_;
  const fs::path work_dir_, log_, database_;
  const std::string image_path_, exe_, threads_;
  ColmapReport* report_;
  std::vector<std::string> image_names_;
  int total_ = 0;
  fs::path best_;
  int best_registered_ = 0, runs_ = 0;
};

Status ColmapJob::ChooseImages() {
  RemoveAll(database_);
  const bool several = capture_.cameras.size() > 1;
  report_->matcher = options_.matcher == "auto" ? (several ? "exhaustive" : "sequential") : options_.matcher;
  report_->mask =
      options_.mask == "auto" ? (several && !options_.static_cameras ? "background" : "none") : options_.mask;
  std::vector<std::vector<size_t>> chosen(capture_.cameras.size());
  for (size_t c = 0; c < capture_.cameras.size(); ++c) {
    const size_t n = capture_.cameras[c].frames.size();
    if (options_.static_cameras) {
      const size_t k = std::min<size_t>(n, options_.rig_instants);
      for (size_t i = 0; i < k; ++i) chosen[c].push_back(k > 1 ? i * (n - 1) / (k - 1) : 0);
    } else {
      for (size_t i = 0; i < n; i += options_.frame_step) chosen[c].push_back(i);
    }
  }
  std::string names;
  for (size_t c = 0; c < capture_.cameras.size(); ++c)
    for (size_t i : chosen[c]) {
      image_names_.push_back(capture_.cameras[c].name + "/" + FrameFileName(capture_.cameras[c].frames[i].index));
      names += image_names_.back() + "\n";
    }
  HF_RETURN_IF_ERROR(WriteFileAtomic(work_dir_ / "images.txt", names));
  total_ = static_cast<int>(image_names_.size());
  report_->total = total_;
  if (report_->mask == "none") return Status::Ok();
  // COLMAP reads <mask_path>/<image name>.png and ignores pixels that are 0.
  for (size_t c = 0; c < capture_.cameras.size(); ++c)
    for (size_t i : chosen[c]) {
      const IngestedCamera& cam = capture_.cameras[c];
      cv::Mat head = cv::imread(capture_.MaskPath(cam.name, cam.frames[i].index).string(), cv::IMREAD_GRAYSCALE);
      if (head.empty()) return Status::DataError("missing mask for " + cam.name + " frame " + std::to_string(i));
      const cv::Mat keep = report_->mask == "head" ? head : 255 - head;
      HF_RETURN_IF_ERROR(
          WriteImageAtomic(work_dir_ / "masks" / cam.name / (FrameFileName(cam.frames[i].index) + ".png"), keep));
    }
  return Status::Ok();
}

Status ColmapJob::ExtractFeatures() {
  std::vector<std::string> extract = {exe_, "feature_extractor", "--database_path", database_.string(),
                                      "--image_path", image_path_, "--image_list_path", (work_dir_ / "images.txt").string(),
                                      "--ImageReader.camera_model", options_.camera_model,
                                      "--ImageReader.single_camera_per_folder", "1",
                                      "--SiftExtraction.use_gpu", "0",
                                      "--SiftExtraction.num_threads", threads_,
                                      "--SiftExtraction.max_num_features", std::to_string(options_.max_features)};
  if (report_->mask != "none") {
    extract.push_back("--ImageReader.mask_path");
    extract.push_back((work_dir_ / "masks").string());
  }
  HF_LOG(Info) << "calibrate: COLMAP feature extraction on " << total_ << " images (" << options_.max_features
               << " SIFT features max, mask: " << report_->mask << ")";
  return RunTool(extract, log_);
}

Status ColmapJob::Match(const std::string& matcher) {
  HF_LOG(Info) << "calibrate: COLMAP " << matcher << " matching";
  if (matcher == "sequential")
    return RunTool({exe_, "sequential_matcher", "--database_path", database_.string(), "--SiftMatching.use_gpu", "0",
                    "--SiftMatching.num_threads", threads_, "--SequentialMatching.overlap",
                    std::to_string(options_.overlap), "--SequentialMatching.quadratic_overlap", "1"},
                   log_);
  return RunTool({exe_, "exhaustive_matcher", "--database_path", database_.string(), "--SiftMatching.use_gpu", "0",
                  "--SiftMatching.num_threads", threads_},
                 log_);
}

std::vector<std::string> ColmapJob::SequentialOrder() const {
  std::vector<std::string> order = image_names_;
  std::sort(order.begin(), order.end());
  return order;
}

fs::path ColmapJob::LargestModel(const fs::path& dir, int* registered) {
  fs::path largest;
  *registered = 0;
  if (!fs::is_directory(dir)) return largest;
  for (const auto& entry : fs::directory_iterator(dir)) {
    const int n = entry.is_directory() ? CountRegisteredImages(entry.path() / "images.bin") : 0;
    if (n > *registered) {
      *registered = n;
      largest = entry.path();
    }
  }
  return largest;
}

// The incremental mapper depends on its initial pair and on thread timing: a
// run that registers too few images is repeated with relaxed initialisation
// (the attempts' models are kept side by side), and the largest model wins.
// When both started a model that stopped short (not when neither found a
// pair to start from), the defaults run once more: the same matches gave 24
// of 24 images in most runs and 18 in one.
const std::vector<std::vector<std::string>>& MapperAttempts() {
  static const std::vector<std::vector<std::string>> attempts = {
      {},
      {"--Mapper.init_min_tri_angle", "8", "--Mapper.init_min_num_inliers", "50", "--Mapper.abs_pose_min_num_inliers",
       "15", "--Mapper.min_num_matches", "10"},
      {}};
  return attempts;
}

// The third attempt only follows models that stopped short.
bool MapperAttemptWorthRunning(size_t attempt, int registered_so_far) {
  return attempt < 2 || registered_so_far > 0;
}

// What the log says of attempt `a`.
const char* MapperAttemptLabel(size_t a) {
  return a == 0 ? "" : a == 1 ? " (again, relaxed initialisation)" : " (once more, from another start)";
}

Status ColmapJob::Map() {
  const auto& attempts = MapperAttempts();
  const size_t num_attempts = std::min(attempts.size(), static_cast<size_t>(options_.mapper_attempts));
  for (size_t a = 0; a < num_attempts && MapperAttemptWorthRunning(a, best_registered_); ++a) {
    const int run = runs_++;
    const fs::path sparse = work_dir_ / ("sparse" + (run == 0 ? std::string() : "_" + std::to_string(run)));
    RemoveAll(sparse);
    HF_RETURN_IF_ERROR(EnsureDirectory(sparse));
    HF_LOG(Info) << "calibrate: COLMAP mapper" << MapperAttemptLabel(a);
    std::vector<std::string> mapper = {exe_, "mapper", "--database_path", database_.string(), "--image_path",
                                       image_path_, "--output_path", sparse.string(), "--Mapper.num_threads", threads_};
    mapper.insert(mapper.end(), attempts[a].begin(), attempts[a].end());
    const Status mapped = RunTool(mapper, log_);
    if (!mapped.ok() && a + 1 == num_attempts && best_.empty()) return mapped;
    int registered = 0;
    const fs::path largest = LargestModel(sparse, &registered);
    if (registered > best_registered_) {
      best_registered_ = registered;
      best_ = largest;
    }
    if (Enough()) break;
  }
  return Status::Ok();
}

Status ColmapJob::MapWithFallback() {
  Status mapped = Map();
  const bool sequential = report_->matcher == "sequential";
  constexpr int kMinKeyframes = 16;
  if (sequential && !Enough() && options_.keyframe_step > 0 && total_ / options_.keyframe_step >= kMinKeyframes) {
    report_->sequential_registered = best_registered_;
    for (int step = options_.keyframe_step; !Enough() && total_ / step >= kMinKeyframes; step *= 2) {
      HF_LOG(Warning) << "calibrate: COLMAP registered " << best_registered_ << " of " << total_
                      << " images after sequential matching; mapping one image in " << step
                      << " (frames a few degrees apart give the mapper too little parallax) and "
                      << "registering the rest into that model";
      if (Status s = MapKeyframes(step); !s.ok()) {
        HF_LOG(Warning) << "calibrate: mapping one image in " << step << " failed: " << s.message();
        continue;
      }
      mapped = Status::Ok();
    }
  }
  if (sequential && !Enough() && total_ <= options_.exhaustive_fallback_max) {
    HF_LOG(Warning) << "calibrate: COLMAP registered " << best_registered_ << " of " << total_
                    << " images after sequential matching" << (report_->keyframes ? " and keyframes" : "")
                    << "; matching every pair and mapping again (slow for many frames)";
    if (report_->sequential_registered < 0) report_->sequential_registered = best_registered_;
    report_->exhaustive_fallback = true;
    HF_RETURN_IF_ERROR(Match("exhaustive"));
    mapped = Map();
  }
  HF_RETURN_IF_ERROR(mapped);
  if (best_.empty())
    return Status::DataError("COLMAP reconstructed nothing from " + std::to_string(total_) +
                             " images (too few features or matches: textureless frames? see " + log_.string() + ")");
  return Status::Ok();
}

Status ColmapJob::MapKeyframes(int step) {
  const std::vector<std::string> order = SequentialOrder();
  std::vector<std::string> keyframes;
  for (size_t i = 0; i < order.size(); i += step) keyframes.push_back(order[i]);
  // Keyframes nearer than `overlap` images were matched sequentially; the
  // next `overlap` keyframes beyond them are matched now, as sequential
  // matching of the keyframes alone would.
  std::string key_list, pairs;
  for (size_t a = 0; a < keyframes.size(); ++a) {
    key_list += keyframes[a] + "\n";
    for (size_t b = a + 1; b < keyframes.size() && b <= a + options_.overlap; ++b)
      if (int(b - a) * step > options_.overlap) pairs += keyframes[a] + " " + keyframes[b] + "\n";
  }
  const std::string tag = "keyframes_" + std::to_string(step);
  const fs::path key_path = work_dir_ / (tag + ".txt"), pair_path = work_dir_ / (tag + "_pairs.txt");
  HF_RETURN_IF_ERROR(WriteFileAtomic(key_path, key_list));
  if (!pairs.empty()) {
    HF_RETURN_IF_ERROR(WriteFileAtomic(pair_path, pairs));
    HF_RETURN_IF_ERROR(RunTool({exe_, "matches_importer", "--database_path", database_.string(), "--match_list_path",
                                pair_path.string(), "--match_type", "pairs", "--SiftMatching.use_gpu", "0",
                                "--SiftMatching.num_threads", threads_},
                               log_));
  }
  // The keyframes mapped as Map() maps every image: again with relaxed
  // initialisation while too few register, the largest model kept.
  const auto& attempts = MapperAttempts();
  const size_t num_attempts = std::min(attempts.size(), static_cast<size_t>(options_.mapper_attempts));
  fs::path model;
  int mapped_count = 0;
  for (size_t a = 0; a < num_attempts && mapped_count < options_.retry_below * keyframes.size() &&
                     MapperAttemptWorthRunning(a, mapped_count);
       ++a) {
    const fs::path mapped = work_dir_ / (tag + "_" + std::to_string(a));
    RemoveAll(mapped);
    HF_RETURN_IF_ERROR(EnsureDirectory(mapped));
    HF_LOG(Info) << "calibrate: COLMAP mapper on " << keyframes.size() << " keyframes"
                 << MapperAttemptLabel(a);
    std::vector<std::string> mapper = {exe_, "mapper", "--database_path", database_.string(), "--image_path",
                                       image_path_, "--output_path", mapped.string(), "--image_list_path",
                                       key_path.string(), "--Mapper.num_threads", threads_};
    mapper.insert(mapper.end(), attempts[a].begin(), attempts[a].end());
    if (Status s = RunTool(mapper, log_); !s.ok()) {
      HF_LOG(Info) << "calibrate: " << s.message();  // often no starting pair: the relaxed attempt follows
      continue;
    }
    int count = 0;
    const fs::path largest = LargestModel(mapped, &count);
    if (count > mapped_count) {
      mapped_count = count;
      model = largest;
    }
  }
  if (model.empty()) return Status::DataError("the mapper reconstructed nothing from the keyframes");
  HF_LOG(Info) << "calibrate: COLMAP mapped " << mapped_count << " of " << keyframes.size()
               << " keyframes; registering the images between them";
  // Registered into the keyframes' model, then their points triangulated
  // and the whole bundle adjusted.
  const fs::path registered_dir = work_dir_ / (tag + "_registered"), triangulated = work_dir_ / (tag + "_triangulated"),
                 adjusted = work_dir_ / (tag + "_adjusted");
  for (const fs::path& dir : {registered_dir, triangulated, adjusted}) {
    RemoveAll(dir);
    HF_RETURN_IF_ERROR(EnsureDirectory(dir));
  }
  HF_RETURN_IF_ERROR(RunTool({exe_, "image_registrator", "--database_path", database_.string(), "--input_path",
                              model.string(), "--output_path", registered_dir.string(), "--Mapper.num_threads",
                              threads_},
                             log_));
  HF_RETURN_IF_ERROR(RunTool({exe_, "point_triangulator", "--database_path", database_.string(), "--image_path",
                              image_path_, "--input_path", registered_dir.string(), "--output_path",
                              triangulated.string(), "--Mapper.num_threads", threads_},
                             log_));
  HF_RETURN_IF_ERROR(RunTool({exe_, "bundle_adjuster", "--input_path", triangulated.string(), "--output_path",
                              adjusted.string()},
                             log_));
  RemoveAll(registered_dir);
  RemoveAll(triangulated);
  const int registered = CountRegisteredImages(adjusted / "images.bin");
  HF_LOG(Info) << "calibrate: COLMAP registered " << registered << " of " << total_ << " images round "
               << mapped_count << " keyframes";
  if (registered > best_registered_) {
    best_registered_ = registered;
    best_ = adjusted;
    report_->keyframe_step = step;
    report_->keyframes = mapped_count;
  }
  return Status::Ok();
}

Status ColmapJob::CloseLoops() {
  if (report_->matcher != "sequential" || report_->exhaustive_fallback || options_.revisit_angle_deg <= 0)
    return Status::Ok();
  const fs::path first = work_dir_ / "model_first";
  RemoveAll(first);
  HF_RETURN_IF_ERROR(EnsureDirectory(first));
  HF_RETURN_IF_ERROR(RunTool({exe_, "model_converter", "--input_path", best_.string(), "--output_path",
                              first.string(), "--output_type", "TXT"},
                             log_));
  ColmapTextModel model;
  std::map<long, Eigen::Vector3d> points;
  HF_RETURN_IF_ERROR(ReadColmapCamerasAndImages(first, &model));
  HF_RETURN_IF_ERROR(ReadColmapPoints(first, &points));
  RemoveAll(first);
  const std::vector<std::string> order = SequentialOrder();
  const auto pairs =
      FindRevisitPairs(model, points, order, options_.revisit_angle_deg, options_.overlap, options_.revisit_pairs);
  if (pairs.empty()) return Status::Ok();
  const fs::path pair_list = work_dir_ / "revisit_pairs.txt";
  std::string text;
  for (const auto& [a, b] : pairs) text += a + " " + b + "\n";
  HF_RETURN_IF_ERROR(WriteFileAtomic(pair_list, text));
  HF_LOG(Info) << "calibrate: the camera comes back to views it saw before: COLMAP matches " << pairs.size()
               << " more pairs of images (looking within " << options_.revisit_angle_deg
               << " deg of each other) and refines the model with them";
  HF_RETURN_IF_ERROR(RunTool({exe_, "matches_importer", "--database_path", database_.string(), "--match_list_path",
                              pair_list.string(), "--match_type", "pairs", "--SiftMatching.use_gpu", "0",
                              "--SiftMatching.num_threads", threads_},
                             log_));
  report_->revisit_pairs = static_cast<int>(pairs.size());
  fs::path refined = best_;
  if (Status s = Refine(&refined); s.ok()) {
    best_ = refined;
  } else {
    HF_LOG(Warning) << "calibrate: refining with the revisited views failed (" << s.message()
                    << "); keeping the first model";
  }
  return Status::Ok();
}

// The first model stays the start: its points are triangulated again with
// the new matches (tracks that span the return merge) and the whole model is
// bundle adjusted, twice (the second pass merges what the first brought
// within reach). Mapping again from scratch instead rolls the incremental
// mapper's dice once more, and it sometimes returns a model that registers
// every image in the wrong places.
Status ColmapJob::Refine(fs::path* refined) {
  for (int round = 1; round <= 2; ++round) {
    const fs::path triangulated = work_dir_ / "revisit_triangulated";
    const fs::path adjusted = work_dir_ / ("revisit_adjusted_" + std::to_string(round));
    for (const fs::path& dir : {triangulated, adjusted}) {
      RemoveAll(dir);
      HF_RETURN_IF_ERROR(EnsureDirectory(dir));
    }
    HF_RETURN_IF_ERROR(RunTool({exe_, "point_triangulator", "--database_path", database_.string(), "--image_path",
                                image_path_, "--input_path", refined->string(), "--output_path",
                                triangulated.string(), "--Mapper.num_threads", threads_},
                               log_));
    HF_RETURN_IF_ERROR(RunTool({exe_, "bundle_adjuster", "--input_path", triangulated.string(), "--output_path",
                                adjusted.string()},
                               log_));
    RemoveAll(triangulated);
    if (*refined != best_) RemoveAll(*refined);
    *refined = adjusted;
  }
  return Status::Ok();
}

Status ColmapJob::ReadModel(CameraSet* cameras) {
  const fs::path text = work_dir_ / "model";
  RemoveAll(text);
  HF_RETURN_IF_ERROR(EnsureDirectory(text));
  HF_RETURN_IF_ERROR(RunTool({exe_, "model_converter", "--input_path", best_.string(), "--output_path", text.string(),
                              "--output_type", "TXT"},
                             log_));
  HF_RETURN_IF_ERROR(ReadColmapTextModel(text, capture_, cameras, report_));
  report_->total = total_;
  return Status::Ok();
}

Status ColmapJob::HoldFixedCameraPoses(CameraSet* cameras) const {
  if (!options_.static_cameras) return Status::Ok();
  if (Status s = CheckFixedCameraInstants(*cameras, options_.max_instant_rotation_deg, options_.max_instant_shift);
      !s.ok())
    return Status::DataError("COLMAP's model is inconsistent: " + s.message() +
                             "; --max-instant-rotation and --max-instant-shift set the limits; fewer "
                             "--rig-instants or a rig file (--mode rig) may help; see " + log_.string());
  // Registration counts the instants COLMAP was given.
  std::map<std::string, Eigen::Isometry3d> pose;
  for (const auto& v : cameras->views)
    if (v.registered && !pose.count(v.camera)) pose[v.camera] = v.cam_from_world;
  for (auto& v : cameras->views) {
    const auto it = pose.find(v.camera);
    v.registered = it != pose.end();
    if (v.registered) v.cam_from_world = it->second;
  }
  return Status::Ok();
}

}  // namespace

Status RunColmap(const ColmapOptions& options, const IngestedCapture& capture, const fs::path& work_dir,
                 CameraSet* cameras, ColmapReport* report) {
  HF_RETURN_IF_ERROR(options.Check());
  const auto start = std::chrono::steady_clock::now();
  HF_RETURN_IF_ERROR(EnsureDirectory(work_dir));
  ColmapJob job(options, capture, work_dir, report);
  HF_RETURN_IF_ERROR(job.ChooseImages());
  HF_RETURN_IF_ERROR(job.ExtractFeatures());
  HF_RETURN_IF_ERROR(job.Match(report->matcher));
  HF_RETURN_IF_ERROR(job.MapWithFallback());
  HF_RETURN_IF_ERROR(job.CloseLoops());
  HF_RETURN_IF_ERROR(job.ReadModel(cameras));
  HF_RETURN_IF_ERROR(job.HoldFixedCameraPoses(cameras));
  report->seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return Status::Ok();
}

}  // namespace headforge
