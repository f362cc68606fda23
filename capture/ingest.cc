#include "capture/ingest.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <set>

#include "capture/background_motion.h"
#include "capture/capture_io.h"
#include "capture/crop.h"
#include "capture/face_choice.h"
#include "capture/frame_selection.h"
#include "capture/frame_source.h"
#include "capture/landmarks.h"
#include "capture/sharpness.h"
#include "core/image_io.h"
#include "core/json_io.h"
#include "core/log.h"
#include "core/parallel.h"
#include "core/paths.h"
#include "vision/face_mesh.h"

namespace headforge {

namespace {

// Per camera: source, offset, and the analysis of each sampled frame by sample index.
struct Camera {
  std::string name;
  std::unique_ptr<FrameSource> source;
  StreamCheck stream;  // ffmpeg's verdict on a video source
  int offset = 0;
  std::map<int, FrameAnalysis> analysis;  // sample index k -> analysis
  double median_sharpness = 0.0;
  int64_t stream_end = -1;  // frames the source gave before it ended while samples were wanted; -1: did not
};

// The source frame index of sample k in the reference (first) camera: every
// source/--fps-th frame, or for a variable frame rate the frame nearest each
// multiple of 1/rate() on the timestamps' axis.
class SamplePlan {
 public:
  SamplePlan(const IngestOptions& options, const FrameSource& reference) {
    max_frames_ = options.max_frames > 0 ? options.max_frames : (1 << 30);
    if (!reference.variable_rate()) {
      const double source_fps = reference.fps();
      rate_ = options.fps > 0.0 ? std::min(options.fps, source_fps) : source_fps;
      step_ = options.fps > 0.0 ? std::max(1.0, source_fps / options.fps) : 1.0;
      first_ = options.start * source_fps;
      last_ = options.end > 0.0 ? options.end * source_fps : 1e300;
      return;
    }
    by_time_ = true;
    rate_ = options.fps > 0.0 ? std::min(options.fps, reference.mean_fps()) : reference.mean_fps();
    const std::vector<double>& times = reference.timestamps();
    const double end = std::min(options.end > 0.0 ? options.end : 1e300, times.back() + 0.5 / rate_);
    int64_t previous = -1;
    for (int64_t k = 0; static_cast<int>(indices_.size()) < max_frames_; ++k) {
      const double t = options.start + k / rate_;
      if (t >= end) break;
      // The frame nearest t.
      size_t i = std::lower_bound(times.begin(), times.end(), t) - times.begin();
      if (i == times.size() || (i > 0 && t - times[i - 1] < times[i] - t)) --i;
      if (static_cast<int64_t>(i) <= previous) continue;  // a gap in the stream: no new frame near t
      indices_.push_back(static_cast<int64_t>(i));
      previous = static_cast<int64_t>(i);
    }
  }
  // -1 when sample k lies outside the range.
  int64_t SourceIndex(int k) const {
    if (k >= max_frames_) return -1;
    if (by_time_) return static_cast<size_t>(k) < indices_.size() ? indices_[k] : -1;
    const double index = std::ceil(first_ + k * step_ - 1e-9);
    if (index >= last_) return -1;
    return static_cast<int64_t>(index);
  }
  int max_frames() const { return max_frames_; }
  // Samples per second of the capture.
  double rate() const { return rate_; }

 private:
  double step_ = 1.0, first_ = 0.0, last_ = 1e300, rate_ = 0.0;
  int max_frames_;
  bool by_time_ = false;
  std::vector<int64_t> indices_;  // by_time_: sample -> source frame
};

std::string CameraName(int index) { return "cam" + std::to_string(index); }

std::string FrameFile(int index) {
  char name[32];
  std::snprintf(name, sizeof(name), "%06d.png", index);
  return name;
}

// Workers' own detectors; the landmark predictor is shared (thread-safe).
struct Analysers {
  std::vector<std::unique_ptr<FaceDetector>> detectors;
  std::unique_ptr<LandmarkPredictor> landmarks;
};

FrameAnalysis Analyse(const cv::Mat& frame, FaceDetector* detector,
                      const LandmarkPredictor& predictor) {
  constexpr int kMaxCandidates = 3;
  FrameAnalysis a;
  a.sharpness = LaplacianVariance(frame);
  const auto detections = detector->Detect(frame);
  for (size_t i = 0; i < detections.size() && static_cast<int>(i) < kMaxCandidates; ++i) {
    FaceCandidate c;
    c.detection = detections[i];
    c.landmarks = predictor.Predict(frame, detections[i].landmark_box);
    c.plausible = PlausibleFaceLayout(c.landmarks);
    a.faces.push_back(c);
  }
  return a;
}

// Decodes camera `cam` and analyses every frame the plan samples.
Status AnalyseCamera(Camera* cam, const SamplePlan& plan, int threads, Analysers* analysers,
                     Progress* progress) {
  std::map<int64_t, int> wanted;  // own source frame -> sample index, built lazily
  int next_k = 0;
  auto extend = [&](int64_t up_to) {
    while (next_k < plan.max_frames()) {
      const int64_t s = plan.SourceIndex(next_k);
      if (s < 0) {
        next_k = plan.max_frames();
        break;
      }
      const int64_t own = s + cam->offset;
      if (own > up_to) break;
      if (own >= 0) wanted[own] = next_k;
      ++next_k;
    }
  };

  constexpr int kBatch = 16;
  std::vector<std::pair<int, cv::Mat>> batch;  // (k, frame)
  std::vector<std::pair<int64_t, int>> batch_sources;
  auto flush = [&]() {
    std::vector<FrameAnalysis> results(batch.size());
    ParallelFor(static_cast<int>(batch.size()), threads, [&](int i, int worker) {
      results[i] = Analyse(batch[i].second, analysers->detectors[worker].get(), *analysers->landmarks);
    });
    for (size_t i = 0; i < batch.size(); ++i) {
      results[i].source_index = batch_sources[i].first;
      cam->analysis[batch[i].first] = std::move(results[i]);
    }
    progress->Advance(static_cast<int64_t>(batch.size()));
    batch.clear();
    batch_sources.clear();
  };

  for (int64_t j = 0;; ++j) {
    extend(j);
    const auto it = wanted.find(j);
    if (it == wanted.end()) {
      if (next_k >= plan.max_frames() && (wanted.empty() || j > wanted.rbegin()->first)) break;
      if (!cam->source->Skip()) {
        cam->stream_end = j;
        break;
      }
      continue;
    }
    cv::Mat frame;
    bool end = false;
    HF_RETURN_IF_ERROR(cam->source->Read(&frame, &end));
    if (end) {
      cam->stream_end = j;
      break;
    }
    batch.emplace_back(it->second, frame);
    batch_sources.emplace_back(j, it->second);
    if (static_cast<int>(batch.size()) >= kBatch) flush();
  }
  if (!batch.empty()) flush();
  return Status::Ok();
}

Status LoadUserMasks(const IngestOptions& options, const std::string& camera, int cameras,
                     std::vector<fs::path>* files) {
  fs::path dir = options.masks;
  std::error_code ec;
  if (fs::is_directory(dir / camera, ec)) {
    dir = dir / camera;
  } else if (cameras > 1) {
    return Status::NotFound("--mask-folder " + options.masks + " needs a sub-folder " + camera +
                            " when there are several cameras");
  }
  if (!fs::is_directory(dir, ec)) return Status::NotFound("mask folder not found: " + dir.string());
  *files = ListFiles(dir, ImageExtensions());
  if (files->empty()) return Status::DataError("mask folder " + dir.string() + " holds no images");
  return Status::Ok();
}

// Per camera: the face chosen in each kept frame, the crops, the user's masks.
struct CameraPlan {
  std::vector<const FaceCandidate*> faces;  // per kept frame; nullptr where lost
  std::vector<std::vector<cv::Point3f>> meshes;  // per kept frame, frame pixels; empty where none
  std::vector<float> mesh_scores;
  std::vector<FaceFrame> face_frames;       // per kept frame; lost frames borrow the nearest face
  std::vector<CropWindow> crops;
  std::vector<fs::path> user_masks;
};

// Opens every input first, so that a bad one fails before any work, and has
// ffmpeg decode each video whole: damage OpenCV would pass over silently is
// said in the log and the summary.
Status OpenCameras(const IngestOptions& options, std::vector<Camera>* cameras, IngestSummary* summary) {
  cameras->resize(options.inputs.size());
  for (size_t c = 0; c < options.inputs.size(); ++c) {
    Camera& cam = (*cameras)[c];
    cam.name = CameraName(static_cast<int>(c));
    cam.offset = options.offsets.empty() ? 0 : options.offsets[c];
    HF_RETURN_IF_ERROR(FrameSource::Open(options.inputs[c], options.folder_fps, &cam.source));
    if (!cam.source->is_folder()) {
      HF_RETURN_IF_ERROR(CheckVideoStream(options.inputs[c], &cam.stream));
      if (!cam.stream.checked) HF_LOG(Debug) << "ingest: no ffmpeg program to check " << cam.source->path();
      if (cam.stream.errors > 0) {
        const std::string what = cam.source->path() + ": ffmpeg's decoder reports " +
                                 std::to_string(cam.stream.errors) + " error(s) (first: " + cam.stream.first_error +
                                 "): the file is damaged or truncated, and frames may be missing or garbled";
        HF_LOG(Warning) << "ingest: " << what << "; re-export or re-encode it if you can";
        summary->damaged.push_back(what);
      }
    }
    const double first_fps = (*cameras)[0].source->fps();
    if (c > 0 && std::abs(cam.source->fps() - first_fps) > 0.01 * first_fps)
      HF_LOG(Warning) << cam.source->path() << " runs at " << cam.source->fps() << " fps, the first input at "
                      << first_fps << " fps; cameras are paired by frame index (plus --offsets)";
  }
  return Status::Ok();
}

// A video whose stream ended well before the frame count its container
// declares (a decoding error, a file cut short in a copy): said with both
// counts, as a damaged input, before its few frames travel further.
void WarnIfCutShort(const Camera& cam, IngestSummary* summary) {
  const int64_t declared = cam.source->frame_count_hint();
  if (cam.source->is_folder() || cam.stream_end < 0 || declared <= 0) return;
  // The declared count is an estimate in some containers (duration times
  // rate): a few frames short is not damage.
  if (cam.stream_end + std::max<int64_t>(5, declared / 20) >= declared) return;
  const std::string what = cam.source->path() + ": the video ended after " + std::to_string(cam.stream_end) +
                           " frames where its container declares " + std::to_string(declared) +
                           ": a decoding error or a truncated file cut it short";
  HF_LOG(Warning) << "ingest: " << what << "; only those frames are used (re-copy or re-encode the file to use it all)";
  summary->damaged.push_back(what);
}

// Pass 1: sharpness, faces and landmarks of every sampled frame of every camera.
Status AnalyseCameras(const IngestOptions& options, const SamplePlan& plan, int threads, Progress* progress,
                      std::vector<Camera>* cameras) {
  Analysers analysers;
  HF_RETURN_IF_ERROR(LandmarkPredictor::Load(options.landmark_model, &analysers.landmarks));
  analysers.landmarks->set_magnification(options.landmark_magnification);
  for (int w = 0; w < threads; ++w) {
    std::unique_ptr<FaceDetector> detector;
    HF_RETURN_IF_ERROR(FaceDetector::Create(options.detector, &detector));
    analysers.detectors.push_back(std::move(detector));
  }
  // OpenCV's own threads would compete with ours.
  const int opencv_threads = cv::getNumThreads();
  cv::setNumThreads(1);
  struct RestoreThreads {
    int n;
    ~RestoreThreads() { cv::setNumThreads(n); }
  } restore{opencv_threads};

  for (auto& cam : *cameras) {
    int64_t expected = 0;
    const int64_t hint = cam.source->frame_count_hint();
    for (int k = 0; k < plan.max_frames(); ++k) {
      const int64_t s = plan.SourceIndex(k);
      if (s < 0 || (hint > 0 && s + cam.offset >= hint)) break;
      ++expected;
    }
    progress->Start("ingest: analysing " + cam.name, expected);
    HF_RETURN_IF_ERROR(AnalyseCamera(&cam, plan, threads, &analysers, progress).WithContext(cam.source->path()));
    progress->Finish(std::to_string(cam.analysis.size()) + " frames");
    if (cam.analysis.empty()) {
      const double length = hint > 0 ? hint / cam.source->fps() : 0.0;
      return Status::DataError("the time range holds no frame of " + cam.source->path() +
                               (length > 0 ? " (about " + std::to_string(length).substr(0, 5) + " s long)"
                                           : std::string()) +
                               "; check --start, --end and --offsets");
    }
  }
  return Status::Ok();
}

// Synchronises the cameras: a sample is kept when every camera has it and
// none is blurred; the others are recorded in `dropped` with the reason.
Status KeepSamples(const IngestOptions& options, std::vector<Camera>* cameras, std::vector<int>* kept,
                   std::vector<DroppedSample>* dropped, IngestSummary* summary) {
  std::set<int> all_samples;
  for (const auto& cam : *cameras)
    for (const auto& [k, a] : cam.analysis) all_samples.insert(k);
  for (auto& cam : *cameras) {
    std::vector<double> values;
    for (const auto& [k, a] : cam.analysis) values.push_back(a.sharpness);
    BlurredFrames(values, 0.0, &cam.median_sharpness);
  }
  for (int k : all_samples) {
    std::string reason, detail;
    for (const auto& cam : *cameras) {
      const auto it = cam.analysis.find(k);
      if (it == cam.analysis.end()) {
        reason = "missing";
        detail = cam.name + " has no frame for this sample (its video ended, or offsets)";
        break;
      }
      if (options.blur_ratio > 0.0 && it->second.sharpness < options.blur_ratio * cam.median_sharpness) {
        reason = "blur";
        char text[160];
        std::snprintf(text, sizeof(text), "%s sharpness %.1f < %.2f x median %.1f", cam.name.c_str(),
                      it->second.sharpness, options.blur_ratio, cam.median_sharpness);
        detail = text;
        break;
      }
    }
    if (reason.empty()) {
      kept->push_back(k);
      continue;
    }
    DroppedSample d{k, {}, reason, detail};
    for (const auto& cam : *cameras) {
      const auto it = cam.analysis.find(k);
      if (it != cam.analysis.end()) d.source_frames[cam.name] = it->second.source_index;
    }
    dropped->push_back(d);
    (reason == "blur" ? summary->dropped_blur : summary->dropped_missing)++;
  }
  summary->sampled = static_cast<int>(all_samples.size());
  summary->kept = static_cast<int>(kept->size());
  summary->cameras = static_cast<int>(cameras->size());
  if (kept->empty())
    return Status::DataError("all " + std::to_string(all_samples.size()) + " sampled frames were dropped (" +
                             std::to_string(summary->dropped_blur) + " blurred, " +
                             std::to_string(summary->dropped_missing) +
                             " missing in a camera); try --blur-ratio 0 or check --offsets");
  HF_LOG(Info) << "ingest: " << kept->size() << " of " << all_samples.size() << " frames kept, "
               << summary->dropped_blur << " dropped as blurred, " << summary->dropped_missing
               << " missing in a camera";
  return Status::Ok();
}

// A long recording's frames chosen for what they show (frame_selection.h);
// the others are dropped as "unselected".
void SelectByCoverage(int budget, int seed, const std::vector<Camera>& cameras, std::vector<int>* kept,
                      std::vector<DroppedSample>* dropped, IngestSummary* summary) {
  const Camera& cam = cameras[0];
  std::vector<const FrameAnalysis*> frames;
  for (int k : *kept) frames.push_back(&cam.analysis.at(k));
  const CoverageSelection selection = SelectForCoverage(frames, SelectFaces(frames).faces, budget, seed);
  if (selection.round_the_head)
    HF_LOG(Info) << "ingest: " << selection.without_face << " of " << frames.size()
                 << " frames show no face (a camera going round the head?): frames chosen evenly in time";
  const std::set<size_t> chosen(selection.chosen.begin(), selection.chosen.end());
  std::vector<int> selected;
  for (size_t i = 0; i < kept->size(); ++i) {
    if (chosen.count(i)) {
      selected.push_back((*kept)[i]);
      continue;
    }
    DroppedSample d{(*kept)[i], {}, "unselected", "not among the frames chosen for coverage (--select)"};
    for (const auto& c : cameras) {
      const auto it = c.analysis.find((*kept)[i]);
      if (it != c.analysis.end()) d.source_frames[c.name] = it->second.source_index;
    }
    dropped->push_back(d);
  }
  if (!selection.round_the_head)
    HF_LOG(Info) << "ingest: " << selected.size() << " of " << kept->size()
                 << " frames selected for their coverage of head poses and expressions (--select " << budget << ", "
                 << selection.groups << " groups of the face's landmark shapes)";
  summary->dropped_unselected = int(kept->size() - selected.size());
  summary->kept = int(selected.size());
  *kept = std::move(selected);
}

// Faces per camera over the kept frames; lost frames borrow the nearest face for cropping.
Status PlanFaces(const IngestOptions& options, const std::vector<Camera>& cameras, const std::vector<int>& kept,
                 std::vector<CameraPlan>* plans, IngestSummary* summary) {
  plans->assign(cameras.size(), CameraPlan());
  for (size_t c = 0; c < cameras.size(); ++c) {
    const Camera& cam = cameras[c];
    CameraPlan& plan = (*plans)[c];
    std::vector<const FrameAnalysis*> frames;
    for (int k : kept) frames.push_back(&cam.analysis.at(k));
    const FaceChoice choice = SelectFaces(frames);
    plan.faces = choice.faces;
    if (choice.others > 0) {
      char text[300];
      std::snprintf(text, sizeof(text),
                    "%s: %d faces seen; following the largest, most persistent one (in %d of %zu frames, %.0f px "
                    "wide); %d other%s ignored (the strongest in %d frames, %.0f px wide)",
                    cam.name.c_str(), choice.others + 1, choice.followed_frames, kept.size(), choice.followed_width,
                    choice.others, choice.others > 1 ? "s" : "", choice.other_frames, choice.other_width);
      HF_LOG(Info) << "ingest: " << text;
      summary->faces.push_back(text);
    }
    const int found = static_cast<int>(
        std::count_if(plan.faces.begin(), plan.faces.end(), [](auto* f) { return f != nullptr; }));
    if (!options.masks.empty())
      HF_RETURN_IF_ERROR(LoadUserMasks(options, cam.name, static_cast<int>(cameras.size()), &plan.user_masks));
    // A camera of several that never sees the face (behind or beside the
    // head, in a dome) is kept whole, without landmarks, when masks are given:
    // COLMAP places it and the gan-avatar model learns the head from it.
    const bool whole = options.crop == "none" || (options.crop == "auto" && cameras.size() > 1);
    if (found == 0 && cam.stream.errors == 0 && cameras.size() > 1 && whole && !plan.user_masks.empty()) {
      HF_LOG(Warning) << "ingest: " << cam.name << ": no face in any of its " << kept.size()
                      << " frames (a camera behind or beside the head?): kept whole, without landmarks, with the "
                         "masks of --mask-folder";
      summary->face_lost += static_cast<int>(kept.size());
      continue;
    }
    if (found == 0) {
      if (cam.stream.errors > 0)
        return Status::DataError("no face found in " + cam.source->path() + ", which is damaged or truncated "
                                 "(ffmpeg: " + cam.stream.first_error + "): re-export or re-encode the video");
      return Status::DataError(
          "no face found in " + cam.source->path() + " (" + std::to_string(kept.size()) +
          " frames examined). Try: --detector dlib-hog or ultraface-640 (small faces), a lower "
          "--detector-threshold, a video where the face is frontal and well lit, or a higher "
          "resolution source" +
          (cameras.size() > 1 ? std::string("; a camera of several that never sees the face (behind the head) is "
                                            "kept when --mask-folder gives every camera's head masks")
                              : std::string()));
    }
    if (options.min_face_px > 0) {
      std::vector<double> sizes;
      for (const FaceCandidate* f : plan.faces)
        if (f) sizes.push_back(FaceFrameOf(f->landmarks).size);
      std::nth_element(sizes.begin(), sizes.begin() + sizes.size() / 2, sizes.end());
      const double size = sizes[sizes.size() / 2];
      if (size < options.min_face_px)
        return Status::DataError(cam.source->path() + ": the face spans only " + std::to_string(int(size + 0.5)) +
                                 " px of the source (its landmarks, median over the frames): too small to track "
                                 "and to build an avatar from; use a closer or higher-resolution video, or "
                                 "--min-face " + std::to_string(int(size)) + " to go on anyway");
    }
    summary->face_lost += static_cast<int>(kept.size()) - found;
    summary->with_landmarks += found;
    if (found < options.min_face_fraction * kept.size())
      HF_LOG(Warning) << "face found in only " << found << " of " << kept.size() << " frames of "
                      << cam.source->path() << "; the others are kept and marked lost";
    plan.face_frames.resize(kept.size());
    for (size_t i = 0; i < kept.size(); ++i) {
      // Nearest frame with a face, earlier on ties.
      int best = -1;
      for (int d = 0; best < 0; ++d) {
        if (static_cast<int>(i) - d >= 0 && plan.faces[i - d]) best = static_cast<int>(i) - d;
        else if (i + d < kept.size() && plan.faces[i + d]) best = static_cast<int>(i + d);
      }
      plan.face_frames[i] = FaceFrameOf(plan.faces[best]->landmarks);
    }
  }
  return Status::Ok();
}

// The mask of kept frame `i` of a camera: the user's, cropped alike, or the
// masker's (a person matte, or GrabCut seeded from the landmarks: lost frames
// borrow the nearest face).
Status MakeMask(const IngestOptions& options, const Camera& cam, const CameraPlan& plan, const std::vector<int>& kept,
                int i, const cv::Mat& source_frame, const cv::Mat& frame, FrameMasker* masker, cv::Mat* mask) {
  const CropWindow& crop = plan.crops[i];
  if (!plan.user_masks.empty()) {
    const int64_t source_index = cam.analysis.at(kept[i]).source_index;
    if (source_index >= static_cast<int64_t>(plan.user_masks.size()))
      return Status::DataError("no mask for source frame " + std::to_string(source_index) + " of " + cam.name +
                               " in " + options.masks);
    cv::Mat user;
    HF_RETURN_IF_ERROR(ReadImage(plan.user_masks[source_index], &user, cv::IMREAD_GRAYSCALE));
    if (user.size() != source_frame.size())
      return Status::DataError("mask " + plan.user_masks[source_index].string() + " is not the size of its frame");
    *mask = crop.Apply(user, cv::INTER_LINEAR) > 127;
    return Status::Ok();
  }
  const FaceCandidate* face = plan.faces[i];
  for (int d = 1; !face; ++d) {
    if (i - d >= 0 && plan.faces[i - d]) face = plan.faces[i - d];
    else if (i + d < static_cast<int>(kept.size()) && plan.faces[i + d]) face = plan.faces[i + d];
  }
  Landmarks68 mapped;
  for (int p = 0; p < 68; ++p) mapped[p] = crop.Map(face->landmarks[p]);
  const uint64_t seed = static_cast<uint64_t>(options.seed) * 1000003ULL + i + 1;
  if (!crop.Exceeds(source_frame.size())) {
    *mask = masker->Mask(frame, mapped, seed);
    return Status::Ok();
  }
  // Where the crop reaches past the source, the frame is black; a network
  // sees the source's edge repeated instead (black bands make it find
  // shapes there), and nothing out there is the person.
  const bool network = masker->method() != "grabcut";
  *mask = masker->Mask(network ? crop.Apply(source_frame, cv::INTER_LINEAR, cv::BORDER_REPLICATE) : frame, mapped, seed);
  *mask &= crop.Apply(cv::Mat(source_frame.size(), CV_8U, cv::Scalar(255)), cv::INTER_LINEAR) > 127;
  return Status::Ok();
}

// Pass 2 for one camera: decodes again, crops, masks and writes its frames.
// Frame i's face mesh: in the square the 68 points place, then in the one
// its first points place; mapped into the output frame.
void MeshFrame(const IngestOptions& options, const FaceMesh& mesh, const cv::Mat& source, int i, CameraPlan* plan) {
  const FaceCandidate* face = plan->faces[i];
  if (!face) return;
  const std::vector<cv::Point2f> points(face->landmarks.begin(), face->landmarks.end());
  const FaceMeshResult found = mesh.Refine(source, FaceRegionFrom68(points));
  plan->mesh_scores[i] = found.score;
  if (found.score < options.mesh_min_score) return;
  const CropWindow& crop = plan->crops[i];
  std::vector<cv::Point3f>& out = plan->meshes[i];
  for (const cv::Point3f& p : found.points) {
    const cv::Point2f q = crop.Map(cv::Point2f(p.x, p.y));
    out.emplace_back(q.x, q.y, static_cast<float>(p.z * crop.scale));
  }
}

Status WriteCameraFrames(const IngestOptions& options, int camera_index, const Camera& cam, CameraPlan& plan,
                         const std::vector<int>& kept, FrameMasker* masker, const FaceMesh* mesh,
                         const fs::path& out_dir, int threads, Progress* progress) {
  std::unique_ptr<FrameSource> source;
  HF_RETURN_IF_ERROR(FrameSource::Open(options.inputs[camera_index], options.folder_fps, &source));
  const fs::path frame_dir = out_dir / "frames" / cam.name;
  const fs::path mask_dir = out_dir / "masks" / cam.name;
  HF_RETURN_IF_ERROR(EnsureDirectory(frame_dir));
  HF_RETURN_IF_ERROR(EnsureDirectory(mask_dir));
  std::map<int64_t, int> wanted;  // source frame -> output index
  for (size_t i = 0; i < kept.size(); ++i) wanted[cam.analysis.at(kept[i]).source_index] = static_cast<int>(i);

  progress->Start("ingest: writing " + cam.name, static_cast<int64_t>(kept.size()));
  std::vector<std::pair<int, cv::Mat>> batch;
  Status batch_status;
  // A recurrent matte sees the frames one at a time in their order, its
  // state first warmed on the opening frames (cold, it misses parts of the
  // person on the first one or two).
  const bool in_order = plan.user_masks.empty() && masker->sequential();
  masker->StartSequence();
  plan.meshes.assign(kept.size(), {});
  plan.mesh_scores.assign(kept.size(), 0.0f);
  bool warm = false;
  auto flush = [&]() {
    std::vector<Status> statuses(batch.size());
    std::vector<cv::Mat> frames(batch.size()), masks(batch.size());
    auto crop_and_mask = [&](int b) {
      const int i = batch[b].first;
      if (frames[b].empty()) frames[b] = plan.crops[i].Apply(batch[b].second, cv::INTER_LINEAR);
      statuses[b] = MakeMask(options, cam, plan, kept, i, batch[b].second, frames[b], masker, &masks[b]);
    };
    if (in_order && !warm) {
      constexpr int kWarmFrames = 8;
      for (size_t b = 0; b < batch.size() && b < kWarmFrames; ++b) {
        crop_and_mask(static_cast<int>(b));
        masks[b].release();
      }
      warm = true;
    }
    if (in_order)
      for (size_t b = 0; b < batch.size(); ++b) crop_and_mask(static_cast<int>(b));
    ParallelFor(static_cast<int>(batch.size()), threads, [&](int b, int) {
      if (!in_order) crop_and_mask(b);
      const int i = batch[b].first;
      if (mesh) MeshFrame(options, *mesh, batch[b].second, i, &plan);
      if (statuses[b].ok()) statuses[b] = WriteImageAtomic(frame_dir / FrameFile(i), frames[b]);
      if (statuses[b].ok()) statuses[b] = WriteImageAtomic(mask_dir / FrameFile(i), masks[b]);
    });
    for (const auto& st : statuses)
      if (!st.ok() && batch_status.ok()) batch_status = st;
    progress->Advance(static_cast<int64_t>(batch.size()));
    batch.clear();
  };
  const int64_t last = wanted.rbegin()->first;
  for (int64_t j = 0; j <= last && batch_status.ok(); ++j) {
    const auto it = wanted.find(j);
    if (it == wanted.end()) {
      if (!source->Skip()) break;
      continue;
    }
    cv::Mat frame;
    bool end = false;
    HF_RETURN_IF_ERROR(source->Read(&frame, &end));
    if (end) break;
    batch.emplace_back(it->second, frame);
    if (static_cast<int>(batch.size()) >= 16) flush();
  }
  if (!batch.empty()) flush();
  HF_RETURN_IF_ERROR(batch_status);
  if (ListFiles(frame_dir).size() != kept.size())
    return Status::DataError(cam.source->path() + " yielded fewer frames on the second read than on the first "
                             "(damaged stream?)");
  progress->Finish();
  return Status::Ok();
}

// The record of one camera's kept frames, as capture.json and landmarks.json hold it.
IngestedCamera CameraRecord(const IngestOptions& options, const std::string& crop_mode, const Camera& cam,
                            const CameraPlan& plan, const std::vector<int>& kept, const FrameMasker& masker) {
  IngestedCamera record;
  record.name = cam.name;
  record.source = AbsolutePath(cam.source->path()).string();
  record.source_fps = cam.source->fps();
  record.source_width = cam.source->size().width;
  record.source_height = cam.source->size().height;
  record.offset = cam.offset;
  record.median_sharpness = cam.median_sharpness;
  record.decoder_errors = cam.stream.errors;
  record.decoder_error = cam.stream.first_error;
  record.masks = plan.user_masks.empty() ? masker.method() : "user";
  record.fixed_crop = crop_mode != "frame";
  const CropWindow& first = plan.crops[0];
  record.crop_x0 = first.x0;
  record.crop_y0 = first.y0;
  record.crop_width = first.width;
  record.crop_height = first.height;
  record.crop_scale = first.scale;
  record.width = first.output.width;
  record.height = first.output.height;
  for (size_t i = 0; i < kept.size(); ++i) {
    const FrameAnalysis& a = cam.analysis.at(kept[i]);
    const CropWindow& crop = plan.crops[i];
    IngestedFrame f;
    f.index = static_cast<int>(i);
    f.source_frame = static_cast<int>(a.source_index);
    f.time_s = cam.source->TimeOf(a.source_index);
    f.sharpness = std::round(a.sharpness * 10.0) / 10.0;
    if (cam.source->is_folder()) f.source_file = cam.source->FrameName(a.source_index);
    if (crop_mode == "frame") f.crop = crop;
    if (i < plan.meshes.size()) {
      f.mesh = plan.meshes[i];
      f.mesh_score = plan.mesh_scores[i];
    }
    if (const FaceCandidate* face = plan.faces[i]) {
      Landmarks68 mapped;
      for (int p = 0; p < 68; ++p) {
        const cv::Point2f m = crop.Map(face->landmarks[p]);
        mapped[p] = cv::Point2f(std::round(m.x * 100.0f) / 100.0f, std::round(m.y * 100.0f) / 100.0f);
      }
      f.landmarks = mapped;
      const cv::Point2f tl = crop.Map(face->detection.box.tl());
      const cv::Point2f br = crop.Map(face->detection.box.br());
      f.score = std::round(face->detection.score * 1000.0f) / 1000.0f;
      f.detector = face->detection.from_fallback ? "dlib-hog (fallback)" : options.detector.detector;
      f.box = cv::Rect2f(tl.x, tl.y, br.x - tl.x, br.y - tl.y);
    }
    record.frames.push_back(f);
  }
  return record;
}

// Crops for `crop_mode`, pass 2, and capture.json / landmarks.json.
Status WriteOutputs(const IngestOptions& options, double rate, const std::string& crop_mode,
                    const std::vector<Camera>& cameras, std::vector<CameraPlan>* plans, const std::vector<int>& kept,
                    const std::vector<DroppedSample>& dropped, const IngestSummary& summary, FrameMasker* masker,
                    const FaceMesh* mesh, const fs::path& out_dir, int threads, Progress* progress) {
  IngestedCapture capture;
  capture.fps = rate;
  capture.resolution = options.resolution;
  capture.crop_mode = crop_mode;
  capture.samples = kept;
  capture.dropped = dropped;
  capture.counts = {summary.sampled,   summary.kept,      summary.dropped_blur,
                    summary.dropped_missing, summary.face_lost, summary.with_landmarks};
  for (size_t c = 0; c < cameras.size(); ++c) {
    CameraPlan& plan = (*plans)[c];
    if (crop_mode == "sequence") {
      plan.crops.assign(kept.size(), SequenceCrop(plan.face_frames, options.crop_scale, options.resolution));
    } else if (crop_mode == "frame") {
      plan.crops = FollowingCrops(plan.face_frames, options.crop_scale, options.resolution);
    } else {
      plan.crops.assign(kept.size(), FullFrameCrop(cameras[c].source->size(), options.resolution));
    }
    HF_RETURN_IF_ERROR(
        WriteCameraFrames(options, int(c), cameras[c], plan, kept, masker, mesh, out_dir, threads, progress));
    capture.cameras.push_back(CameraRecord(options, crop_mode, cameras[c], plan, kept, *masker));
  }
  return WriteIngestedCapture(capture, out_dir);
}

}  // namespace

Status RunIngest(const IngestOptions& options, const fs::path& out_dir, int threads,
                 Progress* progress, IngestSummary* summary) {
  HF_RETURN_IF_ERROR(options.Check());
  threads = std::max(1, threads);
  *summary = IngestSummary();
  // The matte's network first: a missing or damaged model file fails before any work.
  std::unique_ptr<FrameMasker> masker;
  MatteOptions matte = options.Matte();
  if (!options.masks.empty()) matte.method = "grabcut";  // the user's masks: no network needed
  HF_RETURN_IF_ERROR(FrameMasker::Create(matte, &masker));
  summary->masks = options.masks.empty() ? masker->method() : "user";
  std::unique_ptr<FaceMesh> face_mesh;
  if (options.face_mesh != "off") {
    const Status load =
        FaceMesh::Load(options.vision_models.empty() ? DefaultVisionModelsDir() : options.vision_models, &face_mesh);
    if (!load.ok() && (options.face_mesh == "on" || load.code() != Status::Code::kNotFound))
      return load.WithContext("--face-mesh");
    if (!load.ok()) HF_LOG(Warning) << "ingest: " << load.message() << "; the 68 landmarks stand alone";
  }
  std::vector<Camera> cameras;
  HF_RETURN_IF_ERROR(OpenCameras(options, &cameras, summary));
  const FrameSource& reference = *cameras[0].source;
  if (reference.variable_rate()) {
    char text[200];
    std::snprintf(text, sizeof(text), "%.1f to %.1f fps, %.2f on average", 1.0 / reference.long_interval(),
                  1.0 / reference.short_interval(), reference.mean_fps());
    HF_LOG(Info) << "ingest: " << reference.path() << " has a variable frame rate (" << text
                 << "): frames are sampled by their timestamps";
  }
  const double source_fps = reference.variable_rate() ? reference.mean_fps() : reference.fps();
  if (options.fps > source_fps * 1.001)
    HF_LOG(Warning) << "--fps " << options.fps << " exceeds the source's " << source_fps
                    << " fps; every source frame is used";
  const SamplePlan plan(options, reference);
  HF_RETURN_IF_ERROR(AnalyseCameras(options, plan, threads, progress, &cameras));
  for (const Camera& cam : cameras) WarnIfCutShort(cam, summary);
  std::vector<int> kept;
  std::vector<DroppedSample> dropped;
  HF_RETURN_IF_ERROR(KeepSamples(options, &cameras, &kept, &dropped, summary));
  if (options.select > 0 && int(kept.size()) > options.select)
    SelectByCoverage(options.select, options.seed, cameras, &kept, &dropped, summary);
  std::vector<CameraPlan> plans;
  HF_RETURN_IF_ERROR(PlanFaces(options, cameras, kept, &plans, summary));

  std::string crop_mode = options.crop != "auto" ? options.crop : cameras.size() > 1 ? "none" : "sequence";
  std::string why = options.crop != "auto"    ? "as asked"
                    : cameras.size() > 1 ? "auto: several cameras keep the whole frame, whose background COLMAP needs"
                                         : "auto: one camera";
  HF_RETURN_IF_ERROR(
      WriteOutputs(options, plan.rate(), crop_mode, cameras, &plans, kept, dropped, *summary, masker.get(),
                   face_mesh.get(), out_dir, threads, progress));
  if (options.crop == "auto" && cameras.size() == 1) {
    // A moving camera goes to COLMAP, which needs the background the crop
    // around the head leaves out: measure the motion on what was written, and
    // write the frames again whole if the camera moves.
    IngestedCapture written;
    HF_RETURN_IF_ERROR(ReadIngestedCapture(out_dir, &written));
    BackgroundMotion motion;
    HF_RETURN_IF_ERROR(MeasureBackgroundMotion(written, cameras[0].name, &motion));
    if (motion.Moving(kMovingCameraPx)) {
      crop_mode = "none";
      why = "auto: a moving camera keeps the whole frame for COLMAP";
      HF_LOG(Info) << "ingest: the camera moves (" << motion.Describe() << "); writing the frames again whole";
      std::error_code ec;
      fs::remove_all(out_dir / "frames", ec);
      fs::remove_all(out_dir / "masks", ec);
      HF_RETURN_IF_ERROR(
          WriteOutputs(options, plan.rate(), crop_mode, cameras, &plans, kept, dropped, *summary, masker.get(),
                   face_mesh.get(), out_dir, threads, progress));
    } else {
      why = "auto: one fixed camera; " + motion.Describe();
    }
  }
  summary->crop = crop_mode;
  for (const CameraPlan& p : plans)
    for (const auto& m : p.meshes) summary->with_mesh += !m.empty();
  HF_LOG(Info) << "ingest: crop " << crop_mode << " (" << why << ")";
  return Status::Ok();
}

}  // namespace headforge
