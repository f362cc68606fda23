#include "pipelines/stage_table.h"

#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <sstream>

#include "core/json_io.h"
#include "core/log.h"
#include "pipelines/commands.h"
#include "pipelines/stage_jobs.h"

namespace headforge {

const std::vector<StageEntry>& StageTable() {
  static const std::vector<StageEntry> table = [] {
    std::vector<StageEntry> t(6);
    t[0].name = "ingest";
    t[0].summary = "Turn videos or image folders into frames, landmarks and masks.";
    t[0].usage = "headforge ingest --video FILE|DIR... --workspace DIR [options]";
    t[0].description =
        "Samples frames from one video or image folder per camera, drops blurred frames, detects\n"
        "the face, its 68 landmarks and its 468-point face mesh, crops and resizes around the head,\n"
        "and masks the person (a matting network, or GrabCut without the installed models).";
    t[0].reads = {"the videos or image folders given with --video"};
    t[0].writes = {"frames/", "masks/", "landmarks.json", "capture.json"};
    t[0].version = 5;  // 3: capture.json and landmarks.json carry a version; 4: masks from several GrabCut draws;
                       // 5: person mattes, the face mesh in landmarks.json
    t[0].make = MakeIngestJob;

    t[1].name = "calibrate";
    t[1].upstream = {"ingest"};
    t[1].summary = "Estimate cameras: COLMAP, head pose (fixed camera) or a rig file.";
    t[1].usage = "headforge calibrate --workspace DIR [--mode auto|colmap|head-pose|rig] [options]";
    t[1].description =
        "Estimates the cameras of the ingested frames: COLMAP structure from motion for a moving\n"
        "camera or several cameras, head-pose cameras for a fixed camera (refined with the face\n"
        "model, then by features on the head's rigid part), or a rig file.";
    t[1].reads = {"capture.json", "landmarks.json", "frames/", "masks/"};
    t[1].writes = {"cameras.json", "colmap/ (when COLMAP ran)"};
    t[1].uses_face_model = true;
    // 2: head-pose poses refined with the face model at a focal length the user
    // gave; 3: head-pose poses refined by features on the head's rigid part.
    t[1].version = 3;
    t[1].make = MakeCalibrateJob;

    t[2].name = "align";
    t[2].upstream = {"ingest", "calibrate"};
    t[2].summary = "Align the cameras to the face model's metric head frame (Procrustes).";
    t[2].usage = "headforge align --workspace DIR [options]";
    t[2].description =
        "Aligns the reconstruction to the face model's metric head frame: triangulates the\n"
        "landmarks, fits a similarity by Umeyama's method in RANSAC, then fits the face model to\n"
        "points triangulated on the skin (one camera round a still head; a rig's instants with\n"
        "--align-rig-surface);\n"
        "residuals in mm.";
    t[2].reads = {"capture.json", "landmarks.json", "cameras.json", "frames/"};
    t[2].writes = {"alignment.json", "cameras_head.json"};
    t[2].uses_face_model = true;
    t[2].make = MakeAlignJob;

    t[3].name = "track";
    t[3].upstream = {"ingest", "calibrate", "align"};
    t[3].summary = "Fit the face model (identity, head motion, 53 expressions) to the landmarks.";
    t[3].usage = "headforge track --workspace DIR [options]";
    t[3].description =
        "Fits the face model to the detected landmarks over the whole sequence with Ceres: a\n"
        "shared identity, each frame's head motion (held by head-pose cameras) and 53 blendshape\n"
        "weights in [0, 1], and draws the fitted mesh over the frames.";
    t[3].reads = {"capture.json", "landmarks.json", "cameras_head.json", "frames/"};
    t[3].writes = {"tracking.json", "overlay_<camera>.mp4", "meshes/ (--meshes)"};
    t[3].uses_face_model = true;
    t[3].make = MakeTrackJob;

    t[4].name = "train";
    t[4].version = 3;  // 2: a camera carried round a still head trains one expression on agreed (hull) masks;
                       // 3: the hull's strict vote 0.9 (its bust kept)
    t[4].upstream = {"ingest", "calibrate", "align", "track"};
    t[4].summary = "Train the avatar model on the tracked capture.";
    t[4].usage = "headforge train --workspace DIR [--preset draft|standard|high] [options]";
    t[4].description =
        "Trains the gaussian-style avatar on the frames, masks, head-frame cameras and tracking:\n"
        "stage 1, canonical Gaussians sampled on the tracked mesh and a temporal triplane\n"
        "generator; stage 2, the attention deformation driven by the tracked expressions and\n"
        "head pose, with a loss on the eyes and mouth. The last frames are held out and scored.";
    t[4].reads = {"capture.json", "frames/", "masks/", "cameras_head.json", "tracking.json"};
    t[4].writes = {"models/<model>/ (model.pt, config.json, stats.jsonl, eval.json, previews/, held_out/)"};
    t[4].uses_face_model = true;
    t[4].resumable = true;
    t[4].make = MakeTrainJob;

    t[5].name = "export";
    // Not train: the mesh avatar and the report need only tracking; the
    // trained model's files enter export's fingerprint as its inputs.
    t[5].upstream = {"ingest", "calibrate", "align", "track"};
    t[5].version = 2;  // 2: the Gaussian blendshapes (--formats blendshapes or all) with their GLB
    t[5].summary = "Export the avatar: PLY, glTF, weights, Gaussian blendshapes, videos and a report.";
    t[5].usage = "headforge export --workspace DIR [options]";
    t[5].description =
        "Writes the avatar in the formats other tools open: the mesh avatar as glTF (the tracked\n"
        "identity's mesh, the 53 blendshapes as morph targets with ARKit-style names, the tracked\n"
        "sequence as an animation, a texture baked from the frames), the Gaussians of one pose as\n"
        "PLY and as glTF with KHR_gaussian_splatting, the networks as safetensors with config.json,\n"
        "the Gaussian avatar as linear Gaussian blendshapes (--formats blendshapes; not by default),\n"
        "H.264 videos (the held-out frames beside their renders, an orbit round the head, and a\n"
        "cross-reenactment when --drive names another tracked workspace), a viewer page and\n"
        "report.html, both self-contained. The mesh avatar and the report need only tracking.";
    t[5].reads = {"models/gaussian_style/", "tracking.json", "cameras_head.json", "capture.json", "frames/", "masks/"};
    t[5].writes = {"export/ (avatar_mesh.glb, gaussians.ply, gaussians.glb, weights/, blendshapes/, videos/, "
                   "viewer/index.html, report.html, export.json)"};
    t[5].uses_face_model = true;
    t[5].make = MakeExportJob;
    return t;
  }();
  return table;
}

const StageEntry* FindStage(const std::string& name) {
  for (const StageEntry& e : StageTable())
    if (e.name == name) return &e;
  return nullptr;
}

std::vector<std::string> StageNames() {
  std::vector<std::string> names;
  for (const StageEntry& e : StageTable()) names.push_back(e.name);
  return names;
}

namespace {

std::string Joined(const std::vector<std::string>& items) {
  std::string text;
  for (const auto& item : items) text += (text.empty() ? "" : ", ") + item;
  return text;
}

std::string Description(const StageEntry& entry) {
  std::string text = entry.description + "\nReads: " + Joined(entry.reads) + "\nWrites: " + Joined(entry.writes);
  if (!entry.upstream.empty()) text += "\nNeeds the stages: " + Joined(entry.upstream);
  if (entry.resumable) text += "\nInterrupted (Ctrl-C, a kill), it resumes from its last checkpoint when run again.";
  if (!entry.unavailable.empty()) text += "\nNot available: " + entry.unavailable + ".";
  return text;
}

// Writes to `config` the options ingest last ran with in `workspace` (its
// ingest.ini), for a run that gives no --video, less what the run resolves
// afresh: the data folder's model paths, and the frame budget when a preset
// is given (the preset's). Refuses a relative input that no longer names
// what was ingested (the run is in another folder).
Status RecordedIngestConfig(const fs::path& workspace, bool preset_given, const fs::path& config) {
  std::string text;
  HF_RETURN_IF_ERROR(ReadFileToString(workspace / "ingest.ini", &text));
  nlohmann::json capture;
  HF_RETURN_IF_ERROR(ReadJson(workspace / "capture.json", &capture).WithContext("run without --video"));
  std::vector<fs::path> sources;
  for (const auto& camera : capture.value("cameras", nlohmann::json::array()))
    sources.push_back(fs::weakly_canonical(camera.value("source", "")));
  std::istringstream lines(text);
  std::string kept;
  for (std::string line; std::getline(lines, line);) {
    const size_t eq = line.find(" = ");
    const std::string key = eq == std::string::npos ? "" : line.substr(0, eq);
    const std::string value = eq == std::string::npos ? "" : line.substr(eq + 3);
    if (key == "ultraface_dir" || key == "landmark_model" || (key == "select" && preset_given)) continue;
    if ((key == "video" || key == "masks") && !value.empty() && fs::path(value).is_relative()) {
      std::error_code ec;
      const bool same = key == "masks" ? fs::exists(value, ec)
                                       : std::find(sources.begin(), sources.end(), fs::weakly_canonical(value, ec)) !=
                                             sources.end();
      if (!same)
        return Status::InvalidArgument("run without --video: " + (workspace / "ingest.ini").string() + " gives --" +
                                       key + " " + value + ", relative to the folder ingest ran in, and from here it " +
                                       "names something else; run from that folder, or give --" + key + " again");
    }
    kept += line + "\n";
  }
  return WriteFileAtomic(config, kept);
}

int OpenForWriting(const CommonOptions& common, std::unique_ptr<Workspace>* workspace) {
  if (Status s = Workspace::Open(common.workspace, Workspace::Mode::kReadWrite, workspace); !s.ok())
    return ReportFailure(s);
  return -1;
}

// `headforge run` started once per rank (torchrun, srun): rank 0 runs every
// stage and trains with the others, which wait for it at train (within
// --distributed-timeout), train beside it and end. `*train`: the train
// stage's job where the run reaches it (rank 0 tells the others through it
// once the run ends); `*followed`: this process was a rank above 0 and has
// trained beside rank 0.
Status JoinRanksAtTrain(const std::vector<StageEntry>& table, const std::vector<std::unique_ptr<StageJob>>& jobs,
                        const std::string& until, const StageSettings& settings, const std::string& workspace,
                        StageJob** train, bool* followed) {
  *train = nullptr;
  *followed = false;
  for (size_t i = 0; i < table.size(); ++i) {
    if (table[i].name == "train" && jobs[i] && table[i].unavailable.empty()) *train = jobs[i].get();
    if (table[i].name == until) break;
  }
  if (*train == nullptr) return Status::Ok();
  bool follows = false;
  HF_RETURN_IF_ERROR((*train)->Join(&follows));
  if (!follows) return Status::Ok();
  HF_LOG(Info) << "run: a rank above 0: waiting for rank 0 to run the stages before train";
  HF_RETURN_IF_ERROR((*train)->Follow(settings, workspace));
  *followed = true;
  return Status::Ok();
}

}  // namespace

int StageCommand(const StageEntry& entry, const std::vector<std::string>& args) {
  OptionSet options;
  CommonOptions common;
  AddCommonOptions(&options, &common, /*with_workspace=*/true);
  bool force = false;
  options.Add("force", &force, "Run the stage even when it is up to date (its inputs and options unchanged).", "force",
              OptionSet::Effect::kRuntime);
  std::unique_ptr<StageJob> job = entry.make ? entry.make() : nullptr;
  if (job) job->AddOptions(&options);
  const int parsed = ParseOrExit(&options, args, entry.usage, Description(entry));
  if (parsed >= 0) return parsed;
  if (!job) return ReportFailure(Status::InvalidArgument(entry.name + ": " + entry.unavailable));
  if (Status s = common.Check(true); !s.ok()) return ReportFailure(s);
  const StageSettings settings = common.Settings();
  job->Resolve(settings, options);
  if (Status s = job->Check(); !s.ok()) return ReportFailure(s);
  ApplyCommonOptions(common);
  // Only ingest (and run) make a workspace: another stage on a mistyped path
  // would make an empty one and then ask for ingest.
  if (!entry.upstream.empty() && !Workspace::Exists(common.workspace))
    return ReportFailure(Status::NotFound("no workspace at " + common.workspace +
                                          " (no workspace.json); headforge run --video FILE --workspace " +
                                          common.workspace + " makes one"));
  bool follows = false;
  if (Status s = job->Join(&follows); !s.ok()) return ReportFailure(s);
  if (follows) {
    if (Status s = job->Follow(settings, common.workspace); !s.ok()) return ReportFailure(s);
    return kExitOk;
  }
  std::unique_ptr<Workspace> workspace;
  if (int code = OpenForWriting(common, &workspace); code >= 0) {
    job->Finish();
    return code;
  }
  StderrProgress progress;
  bool skipped = false;
  const Status status = RunStageJob(entry, job.get(), options, workspace.get(), settings, &progress, force, &skipped);
  job->Finish();
  if (!status.ok()) return ReportFailure(status);
  return kExitOk;
}

int RunCommand(const std::vector<std::string>& args) {
  OptionSet options;
  CommonOptions common;
  AddCommonOptions(&options, &common, /*with_workspace=*/true);
  std::string from, until;
  options.Add("from", &from, "Redo the stages from this one on, even when up to date (earlier ones as usual).",
              "from", OptionSet::Effect::kRuntime);
  options.Add("until", &until, "Stop after this stage.", "until", OptionSet::Effect::kRuntime);
  const std::vector<StageEntry>& table = StageTable();
  std::vector<std::unique_ptr<StageJob>> jobs;
  for (const StageEntry& entry : table) {
    jobs.push_back(entry.make ? entry.make() : nullptr);
    if (jobs.back()) jobs.back()->AddOptions(&options);
  }
  const int parsed = ParseOrExit(
      &options, args, "headforge run --video FILE|DIR... --workspace DIR [options]",
      "Runs the pipeline's stages in order into one workspace: " + Joined(StageNames()) +
          " (those available in this version). A stage whose inputs and options are unchanged is\n"
          "skipped; a failed or interrupted one is redone, or resumed from its checkpoint, and one\n"
          "made from outputs that have changed since (headforge status: out of date) is redone.\n"
          "On a workspace already ingested --video may be left out: ingest then runs with the\n"
          "inputs and options it last ran with (WORKSPACE/ingest.ini).\n"
          "Options of every stage are accepted, by their short flag or their dotted key; where two\n"
          "stages share a flag's name the first stage has it and the other is given by its key\n"
          "(--frame-size is ingest's frame size, --train-size the training size). A capture with\n"
          "too few frames to train on stops the run after ingest, before calibrate spends its time.");
  if (parsed >= 0) return parsed;
  // On a workspace already ingested, --video may be left out: ingest's
  // inputs and options are those it last ran with (its ingest.ini), beneath
  // the command line and --config.
  const bool config_given = std::any_of(args.begin(), args.end(), [](const std::string& a) {
    return a == "--config" || a.rfind("--config=", 0) == 0;
  });
  std::error_code ec;
  if (!common.workspace.empty() && !options.WasGiven("ingest.video") && !config_given &&
      fs::is_regular_file(fs::path(common.workspace) / "ingest.ini", ec)) {
    const fs::path config =
        fs::temp_directory_path() / ("headforge_run_" + std::to_string(::getpid()) + "_ingest.ini");
    Status s = RecordedIngestConfig(common.workspace, options.WasGiven("train.preset"), config);
    if (s.ok()) s = options.ApplyConfigBeneath(config.string());
    fs::remove(config, ec);
    if (!s.ok()) return ReportFailure(s);
    HF_LOG(Info) << "run: no --video: ingest's inputs and options as it last ran ("
                 << (fs::path(common.workspace) / "ingest.ini").string() << ")";
  }
  if (Status s = common.Check(true); !s.ok()) return ReportFailure(s);
  for (const std::string* name : {&from, &until}) {
    if (!name->empty() && !FindStage(*name))
      return ReportFailure(Status::InvalidArgument("no stage named '" + *name + "' (the stages: " +
                                                   Joined(StageNames()) + ")"));
  }
  const StageSettings settings = common.Settings();
  // Every stage's options are checked before the first runs, up to --until:
  // the stages after it do not run (a GPU preset's device is not asked of a
  // run that stops before train).
  for (size_t i = 0; i < table.size(); ++i) {
    if (!jobs[i]) continue;
    jobs[i]->Resolve(settings, options);
    if (Status s = jobs[i]->Check(); !s.ok()) return ReportFailure(s);
    if (table[i].name == until) break;
  }
  ApplyCommonOptions(common);
  StageJob* train = nullptr;
  bool followed = false;
  if (Status s = JoinRanksAtTrain(table, jobs, until, settings, common.workspace, &train, &followed); !s.ok())
    return ReportFailure(s);
  if (followed) return kExitOk;
  // The ranks waiting at train are told, however this run ends.
  struct TellWaitingRanks {
    StageJob* job;
    ~TellWaitingRanks() {
      if (job) job->Finish();
    }
  } tell{train};
  std::unique_ptr<Workspace> workspace;
  if (int code = OpenForWriting(common, &workspace); code >= 0) return code;
  StderrProgress progress;
  bool forcing = false;
  std::string last;
  for (size_t i = 0; i < table.size(); ++i) {
    const StageEntry& entry = table[i];
    if (!jobs[i] || !entry.unavailable.empty()) {
      HF_LOG(Info) << "run: " << (last.empty() ? entry.name : last) << " is the last stage available in this version";
      break;
    }
    forcing = forcing || entry.name == from;
    bool skipped = false;
    if (Status s = RunStageJob(entry, jobs[i].get(), options, workspace.get(), settings, &progress, forcing, &skipped);
        !s.ok())
      return ReportFailure(s);
    last = entry.name;
    if (entry.name == until) break;
    // What this stage made may already rule a later one out: say so now,
    // not after the stages between have run.
    for (size_t j = i + 1; j < table.size(); ++j) {
      if (!jobs[j] || !table[j].unavailable.empty()) break;
      if (Status s = jobs[j]->Ahead(common.workspace); !s.ok())
        return ReportFailure(s.WithContext("run: stopped after " + entry.name));
      if (table[j].name == until) break;
    }
  }
  HF_LOG(Info) << "run: results are in " << common.workspace << " (headforge status " << common.workspace << ")";
  // Where the exports are, as export.json lists them (the report first).
  nlohmann::json exported;
  const fs::path out = fs::path(common.workspace) / "export";
  if (last == "export" && ReadJson(out / "export.json", &exported).ok()) {
    std::vector<std::string> files = exported.value("files", std::vector<std::string>());
    std::stable_partition(files.begin(), files.end(), [](const std::string& f) { return f == "report.html"; });
    for (const std::string& f : files)
      if (f != "export.json") std::printf("%s\n", (out / f).c_str());
  }
  return kExitOk;
}

}  // namespace headforge
