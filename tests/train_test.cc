// The train stage end to end on a small simulated capture (talking_static,
// tracked once and shared with track_test), at 48 px and a few hundred
// steps: the loss falls, a second run with the same seed gives the same
// model (20 steps), a run killed outright resumes from its checkpoint to the same
// model, `headforge run` chains train after track and skips it when
// nothing changed, and a workspace that cannot be trained on says what to run.
#include "tests/train_fixture.h"

namespace headforge {
namespace {

// The tracked capture the training tests start from, made by ctest's
// fixture entry before they start (tests/CMakeLists.txt), while unrelated
// tests run beside it, instead of by whichever starts first while the rest
// wait idle.
TEST(SharedWorkspaces, TheTrackedCaptureIsMade) {
  EXPECT_TRUE(fs::exists(TrackedTalkingStatic() / "tracking.json"));
}

TEST_F(TrainStage, TheLossFallsAndTheHeldOutFramesAreScored) {
  ASSERT_EQ(first_.code, 0) << first_.err;
  const fs::path model = reference_ / kModelDir;
  for (const char* file : {"model.pt", "config.json", "stats.jsonl", "eval.json"})
    EXPECT_TRUE(fs::exists(model / file)) << file;
  const std::vector<nlohmann::json> stats = StatsLines(model / "stats.jsonl");
  ASSERT_EQ(stats.size(), 30u);  // a line every 10 steps
  EXPECT_EQ(stats.front()["stage"], 1);
  EXPECT_EQ(stats.back()["stage"], 2);
  // L1 over the masked frame (random backgrounds): the last 50 steps against the first 10.
  const double first = stats.front()["l1"], last = stats.back()["l1"];
  std::printf("L1 %.4f -> %.4f\n", first, last);
  EXPECT_LT(last, 0.7 * first);
  for (const auto& line : stats) EXPECT_TRUE(std::isfinite(line["loss"].get<double>())) << line;

  nlohmann::json eval;
  ASSERT_TRUE(ReadJson(model / "eval.json", &eval).ok());
  EXPECT_EQ(eval["views"].size(), 25u);  // the last 25 of 125 frames
  EXPECT_EQ(CountFiles(model / "held_out"), 25u);
  const double psnr = eval["mean"]["psnr_masked"];
  std::printf("held-out PSNR over the head %.2f dB, training views %.2f dB\n", psnr,
              eval["training_views"]["psnr_masked"].get<double>());
  // The initial Gaussians (one step) score 17.4 dB here; 300 steps at 48 px reach 25.9.
  EXPECT_GT(psnr, 22.0);
  EXPECT_LT(psnr, 60.0);
}

// The reference's options for 20 steps, with the default seed, on a copy
// of the tracked capture: trained once for the tests that compare with it.
std::vector<std::string> ShortOptions() {
  std::vector<std::string> options = TinyOptions();
  *(std::find(options.begin(), options.end(), "--steps") + 1) = "20";
  return options;
}
const fs::path& ShortRun(Result* made) {
  static Result result;
  static const fs::path ws = [] {
    const fs::path dir = CopyOf(TrackedTalkingStatic(), Scratch("short"));
    std::vector<std::string> args = {"train", "--workspace", dir.string()};
    for (const auto& a : ShortOptions()) args.push_back(a);
    result = Headforge(args);
    return dir;
  }();
  *made = result;
  return ws;
}

// The same seed gives the same model (RunChainsTrainAfterTrack... trains
// the short run's options again from nothing through `headforge run`; the
// kill tests resume whole runs to the reference's model), and another seed
// another.
TEST_F(TrainStage, AnotherSeedGivesAnotherModel) {
  Result made;
  const fs::path& short_run = ShortRun(&made);
  ASSERT_EQ(made.code, 0) << made.err;
  const fs::path ws = CopyOf(TrackedTalkingStatic(), Scratch("other_seed"));
  std::vector<std::string> args = {"train", "--workspace", ws.string()};
  for (const auto& a : ShortOptions()) args.push_back(a);
  args.insert(args.end(), {"--train-seed", "5"});
  const Result other = Headforge(args);
  ASSERT_EQ(other.code, 0) << other.err;
  EXPECT_NE(FileHash(ws / kModelDir / "model.pt"), FileHash(short_run / kModelDir / "model.pt"));
}

TEST_F(TrainStage, KilledMidTrainingResumesToTheSameModel) {
  ASSERT_EQ(first_.code, 0) << first_.err;
  const fs::path ws = CopyOf(TrackedTalkingStatic(), Scratch("killed"));
  const fs::path log = fs::temp_directory_path() / "hf_train_killed.log";
  const fs::path staging = ws / ".staging" / "train" / kModelDir;
  // Kill it without warning once a checkpoint past step 100 exists (stats.jsonl
  // has a line every 10 steps).
  ASSERT_TRUE(KillTrainingMidway(TrainArgs(ws), staging, 11, log));
  EXPECT_FALSE(fs::exists(ws / kModelDir / "model.pt"));

  // Resumed on a disk that fills at the next checkpoint (a file-size limit
  // stands in for it): one clear error, the workspace's outputs untouched,
  // and the checkpoint it resumed from kept for the next run.
  const auto before = Snapshot(ws);
  const Result full = HeadforgeWithFileLimit(TrainArgs(ws), 64);
  EXPECT_EQ(full.code, 1) << full.err;
  EXPECT_NE(full.err.find("resuming from the checkpoint at step"), std::string::npos) << full.err;
  EXPECT_NE(full.err.find("checkpoint.pt"), std::string::npos) << full.err;
  EXPECT_NE(full.err.find("ulimit -f, or a full disk"), std::string::npos) << full.err;
  EXPECT_NE(full.err.find("goes on from the stage's last checkpoint"), std::string::npos) << full.err;
  EXPECT_EQ(ReasonLines(full.err).size(), 1u) << full.err;
  EXPECT_EQ(Snapshot(ws), before);
  EXPECT_TRUE(fs::exists(staging / "checkpoint.pt"));

  const Result resumed = Headforge(TrainArgs(ws));
  ASSERT_EQ(resumed.code, 0) << resumed.err;
  EXPECT_NE(resumed.err.find("resuming from the checkpoint at step"), std::string::npos) << resumed.err;
  EXPECT_EQ(FileHash(ws / kModelDir / "model.pt"), FileHash(reference_ / kModelDir / "model.pt"));
  // stats.jsonl lost the lines logged after the checkpoint and has the
  // reference's losses (its times differ).
  const std::vector<nlohmann::json> stats = StatsLines(ws / kModelDir / "stats.jsonl");
  const std::vector<nlohmann::json> expected = StatsLines(reference_ / kModelDir / "stats.jsonl");
  ASSERT_EQ(stats.size(), expected.size());
  for (size_t i = 0; i < stats.size(); ++i) EXPECT_EQ(stats[i]["loss"], expected[i]["loss"]) << i;
  EXPECT_FALSE(fs::exists(ws / kModelDir / "checkpoint.pt"));
}

// --pose-lr: each training view's head-pose correction is trained, kept
// through a kill -9 (the resumed run ends where an uninterrupted one does),
// saved with the model and applied where the training views are scored.
TEST_F(TrainStage, PoseCorrectionsResumeAfterAKillAndScoreTheTrainingViews) {
  ASSERT_EQ(first_.code, 0) << first_.err;
  const auto args = [](const fs::path& ws) {
    std::vector<std::string> a = TrainArgs(ws);
    *(std::find(a.begin(), a.end(), "--steps") + 1) = "60";
    a.insert(a.end(), {"--pose-lr", "1e-3"});
    return a;
  };
  const fs::path whole = CopyOf(TrackedTalkingStatic(), Scratch("pose_whole"));
  const Result straight = Headforge(args(whole));
  ASSERT_EQ(straight.code, 0) << straight.err;
  const std::vector<nlohmann::json> stats = StatsLines(whole / kModelDir / "stats.jsonl");
  ASSERT_FALSE(stats.empty());
  EXPECT_GT(stats.back().value("pose_rotation_deg", 0.0), 0.0) << stats.back();

  const fs::path ws = CopyOf(TrackedTalkingStatic(), Scratch("pose_killed"));
  const fs::path log = fs::temp_directory_path() / "hf_train_pose_killed.log";
  ASSERT_TRUE(KillTrainingMidway(args(ws), ws / ".staging" / "train" / kModelDir, 3, log));
  const Result resumed = Headforge(args(ws));
  ASSERT_EQ(resumed.code, 0) << resumed.err;
  EXPECT_NE(resumed.err.find("resuming from the checkpoint at step"), std::string::npos) << resumed.err;
  EXPECT_EQ(FileHash(ws / kModelDir / "model.pt"), FileHash(whole / kModelDir / "model.pt"));

  // The saved corrections, and the training views' score drawn with them.
  GaussianStyleAvatar avatar;
  FaceModel model;
  DatasetOptions loading;
  AvatarDataset data;
  ASSERT_TRUE(LoadTrained(ws, ws / kModelDir, DefaultDataDir() + "/ict_facekit/ict_face_model.h5", torch::kCPU, 0, &loading, &avatar, &model, &data).ok());
  ASSERT_TRUE(avatar.pose_corrections.defined());
  ASSERT_EQ(avatar.pose_corrections.size(0), int64_t(data.train.size()));
  EXPECT_GT(avatar.pose_corrections.abs().max().item<double>(), 0.0);
  nlohmann::json eval;
  ASSERT_TRUE(ReadJson(ws / kModelDir / "eval.json", &eval).ok());
  const double scored = eval["training_views"]["psnr_masked"];
  const double with = MeanScores(EvaluateAvatar(avatar, data, 10, {}, true)).psnr_masked;
  avatar.pose_corrections = torch::Tensor();
  const double without = MeanScores(EvaluateAvatar(avatar, data, 10, {}, true)).psnr_masked;
  std::printf("training views %.4f dB with the corrections, %.4f dB without\n", with, without);
  EXPECT_NEAR(scored, with, 1e-6);
  EXPECT_NE(with, without);
}

TEST_F(TrainStage, RunChainsTrainAfterTrackAndSkipsItWhenNothingChanged) {
  ASSERT_EQ(first_.code, 0) << first_.err;
  const fs::path ws = CopyOf(TrackedTalkingStatic(), Scratch("run"));
  // Up to train: export's chaining and skipping are ExportStage's.
  std::vector<std::string> args = {"run", "--workspace", ws.string(), "--until", "train", "--video"};
  for (const auto& input : SimulatedInputs(SharedSimulation("talking_static", 125))) args.push_back(input);
  for (const auto& a : ShortOptions()) args.push_back(a);
  const Result first = Headforge(args);
  ASSERT_EQ(first.code, 0) << first.err;
  EXPECT_NE(first.err.find("track: up to date"), std::string::npos) << first.err;
  EXPECT_TRUE(fs::exists(ws / kModelDir / "model.pt"));
  // --model auto chose the gaussian-style model for the one fixed camera, and said so.
  EXPECT_NE(first.err.find("train: gaussian-style (--model auto: one camera"), std::string::npos) << first.err;
  // The short run's options and seed, trained again from nothing: the same model.
  Result made;
  const fs::path& short_run = ShortRun(&made);
  ASSERT_EQ(made.code, 0) << made.err;
  EXPECT_EQ(FileHash(ws / kModelDir / "model.pt"), FileHash(short_run / kModelDir / "model.pt"));
  const Result status = Headforge({"status", ws.string()});
  EXPECT_NE(status.out.find("train      done"), std::string::npos) << status.out;
  EXPECT_NE(status.out.find("auto: one camera"), std::string::npos) << status.out;

  const auto trained_at = fs::last_write_time(ws / kModelDir / "model.pt");
  const Result again = Headforge(args);
  ASSERT_EQ(again.code, 0) << again.err;
  EXPECT_NE(again.err.find("train: up to date"), std::string::npos) << again.err;
  EXPECT_EQ(fs::last_write_time(ws / kModelDir / "model.pt"), trained_at);
}

TEST_F(TrainStage, RenderDrawsAnyFrameFromAnyCamera) {
  ASSERT_EQ(first_.code, 0) << first_.err;
  const fs::path out = Scratch("render");
  const Result r = Headforge({"render", "--workspace", reference_.string(), "--frames", "110,20", "--background", "0.5",
                              "--out", out.string()});
  ASSERT_EQ(r.code, 0) << r.err;
  // Held-out frame 110 from its own camera is what training's evaluation drew
  // (held_out/: render | frame | error).
  const cv::Mat render = cv::imread((out / "frame_000110.png").string());
  const cv::Mat scored = cv::imread((reference_ / kModelDir / "held_out" / "cam0_000110.png").string());
  ASSERT_FALSE(render.empty());
  ASSERT_EQ(scored.cols, 3 * render.cols);
  EXPECT_LE(cv::norm(render, scored(cv::Rect(0, 0, render.cols, render.rows)), cv::NORM_INF), 1.0);
  EXPECT_TRUE(fs::exists(out / "frame_000020.png"));

  // 20 degrees round the head: the same size, another picture.
  const Result turned = Headforge({"render", "--workspace", reference_.string(), "--frames", "110", "--yaw", "20",
                                   "--background", "0.5", "--out", (out / "yaw20").string()});
  ASSERT_EQ(turned.code, 0) << turned.err;
  const cv::Mat side = cv::imread((out / "yaw20" / "frame_000110_yaw+20_pitch+0.png").string());
  ASSERT_EQ(side.size(), render.size());
  EXPECT_GT(cv::norm(side, render, cv::NORM_L1) / double(render.total() * 3), 2.0);
  // Renders from other cameras into one folder sit beside each other: an
  // orbit's three, and frame 110 from below, next to frame 110's own.
  const Result orbit = Headforge({"render", "--workspace", reference_.string(), "--frames", "110", "--orbit", "30",
                                  "--orbit-steps", "3", "--out", out.string()});
  ASSERT_EQ(orbit.code, 0) << orbit.err;
  const Result below = Headforge({"render", "--workspace", reference_.string(), "--frames", "110", "--pitch", "-7.5",
                                  "--out", out.string()});
  ASSERT_EQ(below.code, 0) << below.err;
  for (const char* f : {"frame_000110_orbit30_000.png", "frame_000110_orbit30_001.png", "frame_000110_orbit30_002.png",
                        "frame_000110_yaw+0_pitch-7.5.png"})
    EXPECT_TRUE(fs::exists(out / f)) << f;
  EXPECT_EQ(cv::norm(cv::imread((out / "frame_000110.png").string()), render, cv::NORM_INF), 0.0);

  const Result missing = Headforge({"render", "--workspace", reference_.string(), "--frames", "500", "--out",
                                    out.string()});
  EXPECT_NE(missing.code, 0);
  EXPECT_NE(missing.err.find("'500' names a frame past the last (the frames run 0-124)"), std::string::npos)
      << missing.err;
  // A range with a step, as export --frames reads it.
  const fs::path range = out / "range";
  const Result ranged = Headforge({"render", "--workspace", reference_.string(), "--frames", "120-124:2", "--out",
                                   range.string()});
  ASSERT_EQ(ranged.code, 0) << ranged.err;
  for (const char* file : {"frame_000120.png", "frame_000122.png", "frame_000124.png"})
    EXPECT_TRUE(fs::exists(range / file)) << file;
  EXPECT_FALSE(fs::exists(range / "frame_000121.png"));
}

// Tracking run again after training: the model still renders and exports
// (a model may come from elsewhere, headforge-train on a GPU machine), but
// status, render and export say it is older than the tracking.
TEST_F(TrainStage, AModelOlderThanTheTrackingIsSaidToBe) {
  ASSERT_EQ(first_.code, 0) << first_.err;
  const fs::path ws = CopyOf(reference_, Scratch("retracked"));
  const Result track = Headforge({"track", "--workspace", ws.string(), "--force", "--overlay=false"});
  ASSERT_EQ(track.code, 0) << track.err;
  const Result status = Headforge({"status", ws.string()});
  EXPECT_NE(status.out.find("train      out of date"), std::string::npos) << status.out;
  EXPECT_NE(status.out.find("(track was run again after it)"), std::string::npos) << status.out;
  const std::string warning = "the trained model is older than the tracked capture (track was run again after it)";
  const Result render = Headforge({"render", "--workspace", ws.string(), "--frames", "110", "--out",
                                   (ws / "renders").string()});
  ASSERT_EQ(render.code, 0) << render.err;
  EXPECT_NE(render.err.find("render: " + warning), std::string::npos) << render.err;
  EXPECT_TRUE(fs::exists(ws / "renders" / "frame_000110.png"));
  const Result exported = Headforge({"export", "--workspace", ws.string(), "--formats", "weights"});
  ASSERT_EQ(exported.code, 0) << exported.err;
  EXPECT_NE(exported.err.find("export: " + warning), std::string::npos) << exported.err;
  // The mesh avatar needs only the tracking: nothing to say.
  const Result mesh = Headforge({"export", "--workspace", ws.string(), "--formats", "mesh", "--bake-views", "2",
                                 "--texture-size", "64"});
  ASSERT_EQ(mesh.code, 0) << mesh.err;
  EXPECT_EQ(mesh.err.find(warning), std::string::npos) << mesh.err;
  // An attempt to train again that fails leaves the older model in place,
  // and it is still said to be older.
  const Result failed = Headforge({"train", "--workspace", ws.string(), "--holdout-cameras", "cam9"});
  ASSERT_NE(failed.code, 0);
  EXPECT_NE(failed.err.find("no camera cam9 to hold out"), std::string::npos) << failed.err;
  const Result again = Headforge({"render", "--workspace", ws.string(), "--frames", "110", "--out",
                                  (ws / "renders").string()});
  ASSERT_EQ(again.code, 0) << again.err;
  EXPECT_NE(again.err.find("render: " + warning), std::string::npos) << again.err;
  const Result after = Headforge({"status", ws.string()});
  EXPECT_NE(after.out.find("(the outputs in place are from before: track was run again after it)"), std::string::npos)
      << after.out;
}

TEST_F(TrainStage, HeldOutFramesAreScoredAgainstTheSimulatorsTruth) {
  ASSERT_EQ(first_.code, 0) << first_.err;
  // The capture the workspace came from: its one camera is the training
  // camera, which the novel-view scoring must place exactly where training had it.
  const fs::path out = Scratch("truth");
  const Result r = Headforge({"render", "--workspace", reference_.string(), "--truth",
                              SharedSimulation("talking_static", 125).string(), "--out", out.string()});
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.out.find("| cam0 | +0° / +0° | 25 |"), std::string::npos) << r.out;
  EXPECT_EQ(CountFiles(out), 25u);
  const size_t psnr_at = r.out.find("| 25 | ") + 7;
  const double psnr = std::stod(r.out.substr(psnr_at));
  // Beside it, the workspace's pose through the truth's lens.
  const size_t lens_at = r.out.find(" dB | ", psnr_at) + 6;  // past the frame's PSNR
  const double truth_lens = std::stod(r.out.substr(lens_at));
  std::printf("held-out frames against the simulator's full frames: %.2f dB over the head, %.2f dB through its lens\n",
              psnr, truth_lens);
  // The training camera through its own calibration, its lens carried
  // through ingest's crop onto the truth's whole frames: the held-out
  // frames without the video's noise, scored over the simulator's masks,
  // near eval's figure (drawn with the cropped view's lens unchanged the
  // whole frames scored 17 dB). Through the truth's lens calibrate's focal
  // error (2-3 % here) shows, and can only cost.
  nlohmann::json eval;
  ASSERT_TRUE(ReadJson(reference_ / kModelDir / "eval.json", &eval).ok());
  EXPECT_NEAR(psnr, eval["mean"]["psnr_masked"].get<double>(), 2.0);
  EXPECT_LT(truth_lens, psnr);
  EXPECT_GT(truth_lens, psnr - 8.0);
}

// `render --score-regions`: the held-out frames over the workspace's own
// masks give eval.json's figure; over masks grown by 6 px (a matte that took
// a fringe of the backdrop, which the avatar never painted) they score lower,
// as does the band round those masks' edge; the face scores above the whole
// head. Masks of another crop are refused before anything is drawn.
TEST_F(TrainStage, HeldOutFramesAreScoredOverOtherMasksAndTheirEdge) {
  ASSERT_EQ(first_.code, 0) << first_.err;
  const fs::path grown = CopyOf(TrackedTalkingStatic(), Scratch("grown_masks"));
  const cv::Mat disc = cv::getStructuringElement(cv::MORPH_ELLIPSE, {13, 13});
  for (const auto& entry : fs::directory_iterator(grown / "masks" / "cam0")) {
    cv::Mat mask = cv::imread(entry.path().string(), cv::IMREAD_GRAYSCALE);
    ASSERT_FALSE(mask.empty()) << entry.path();
    cv::dilate(mask, mask, disc);
    ASSERT_TRUE(cv::imwrite(entry.path().string(), mask));
  }
  const fs::path out = Scratch("regions");
  const Result r = Headforge({"render", "--workspace", reference_.string(), "--score-regions", "--score-masks",
                              grown.string(), "--band", "4", "--out", out.string()});
  ASSERT_EQ(r.code, 0) << r.err;
  std::printf("%s", r.out.c_str());
  auto psnr = [&](const std::string& region) {
    const size_t at = r.out.find("| " + region);
    EXPECT_NE(at, std::string::npos) << region << "\n" << r.out;
    if (at == std::string::npos) return 0.0;
    const size_t views = r.out.find("| 25 | ", at);
    EXPECT_NE(views, std::string::npos) << r.out;
    return std::stod(r.out.substr(views + 7));
  };
  const double own = psnr("the workspace's masks"), face = psnr("the face"), other = psnr("the masks of hf_train_grown_masks |"),
               band = psnr("a band 4 px each side");
  nlohmann::json eval;
  ASSERT_TRUE(ReadJson(reference_ / kModelDir / "eval.json", &eval).ok());
  EXPECT_NEAR(own, eval["mean"]["psnr_masked"].get<double>(), 0.005);
  EXPECT_GT(face, own);
  EXPECT_LT(other, own - 1.0);
  EXPECT_LT(band, own - 1.0);  // the edge is where masks and frame disagree most
  EXPECT_EQ(CountFiles(out), 25u * 3);  // the face, the grown masks, the band
  // Masks of another crop do not line up with the frames.
  nlohmann::json capture;
  ASSERT_TRUE(ReadJson(grown / "capture.json", &capture).ok());
  capture["cameras"][0]["crop"]["x0"] = capture["cameras"][0]["crop"]["x0"].get<double>() + 8;
  ASSERT_TRUE(WriteJsonAtomic(grown / "capture.json", capture, 1).ok());
  const Result moved = Headforge({"render", "--workspace", reference_.string(), "--score-regions", "--score-masks",
                                  grown.string()});
  EXPECT_EQ(moved.code, 2) << moved.err;
  EXPECT_NE(moved.err.find("was ingested with another crop"), std::string::npos) << moved.err;
}

// `headforge export` on the trained workspace, once for the tests below.

void EditJson(const fs::path& file, const std::function<void(nlohmann::json*)>& edit) {
  nlohmann::json j;
  ASSERT_TRUE(ReadJson(file, &j).ok()) << file;
  edit(&j);
  ASSERT_TRUE(WriteJsonAtomic(file, j, 1).ok());
}

TEST(TrainBadInput, AWorkspaceWithoutTrackingSaysToRunTrack) {
  const fs::path ws = CopyOf(TrackedTalkingStatic(), Scratch("no_tracking"));
  fs::remove(ws / "tracking.json");
  EditJson(ws / "workspace.json", [](nlohmann::json* j) {
    nlohmann::json kept = nlohmann::json::array();
    for (const auto& stage : (*j)["stages"])
      if (stage["name"] != "track") kept.push_back(stage);
    (*j)["stages"] = kept;
  });
  const Result r = Headforge(TrainArgs(ws));
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.err.find("track"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(ws / kModelDir));
}

TEST(TrainBadInput, TrackingThatDisagreesWithTheFramesIsRefused) {
  const fs::path ws = CopyOf(TrackedTalkingStatic(), Scratch("mismatch"));
  EditJson(ws / "tracking.json", [](nlohmann::json* j) { (*j)["frames"].erase((*j)["frames"].begin() + 100, (*j)["frames"].end()); });
  const Result r = Headforge(TrainArgs(ws));
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.err.find("tracking.json holds 100 frames and the capture 125"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("run headforge track again"), std::string::npos) << r.err;
}

TEST(TrainBadInput, TooFewFramesIsAClearError) {
  const fs::path ws = CopyOf(TrackedTalkingStatic(), Scratch("few"));
  // Six frames in the capture and the tracking alike.
  EditJson(ws / "capture.json", [](nlohmann::json* j) {
    (*j)["frames"].erase((*j)["frames"].begin() + 6, (*j)["frames"].end());
    for (auto& cam : (*j)["cameras"]) cam["frames"].erase(cam["frames"].begin() + 6, cam["frames"].end());
  });
  EditJson(ws / "tracking.json", [](nlohmann::json* j) { (*j)["frames"].erase((*j)["frames"].begin() + 6, (*j)["frames"].end()); });
  const Result r = Headforge(TrainArgs(ws));
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.err.find("the capture has 6 frames"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("ingest a longer video"), std::string::npos) << r.err;

  // `run`'s check after ingest (CheckEnoughFramesToTrain) refuses what the
  // dataset refuses and nothing more: 9 frames leave 7 besides the 2 held
  // out, 10 leave 8.
  FaceModel model;
  ASSERT_TRUE(FaceModel::Load(DefaultDataDir() + "/ict_facekit/ict_face_model.h5", &model).ok());
  nlohmann::json capture, tracking;
  ASSERT_TRUE(ReadJson(TrackedTalkingStatic() / "capture.json", &capture).ok());
  ASSERT_TRUE(ReadJson(TrackedTalkingStatic() / "tracking.json", &tracking).ok());
  for (const int n : {8, 9, 10, 11}) {
    nlohmann::json c = capture, t = tracking;
    c["frames"].erase(c["frames"].begin() + n, c["frames"].end());
    for (auto& cam : c["cameras"]) cam["frames"].erase(cam["frames"].begin() + n, cam["frames"].end());
    t["frames"].erase(t["frames"].begin() + n, t["frames"].end());
    ASSERT_TRUE(WriteJsonAtomic(ws / "capture.json", c).ok());
    ASSERT_TRUE(WriteJsonAtomic(ws / "tracking.json", t).ok());
    DatasetOptions loading;
    loading.images = false;
    AvatarDataset data;
    const Status loaded = LoadAvatarDataset(ws, model, loading, &data);
    const Status ahead = CheckEnoughFramesToTrain(ws, loading.holdout);
    EXPECT_EQ(loaded.ok(), n >= 10) << n << ": " << loaded.message();
    EXPECT_EQ(ahead.ok(), loaded.ok()) << n << ": " << ahead.message();
    if (!ahead.ok()) {
      EXPECT_NE(ahead.message().find("ingest made " + std::to_string(n) + " frames; an avatar needs at least 10"),
                std::string::npos)
          << ahead.message();
    }
  }
}

TEST(TrainHardCases, FramesTheTrackerFlaggedAreLeftOutOfTraining) {
  const fs::path ws = CopyOf(TrackedTalkingStatic(), Scratch("flagged"));
  // Frames 10-29 "failed": interpolated or low-confidence, as the tracker marks them.
  EditJson(ws / "tracking.json", [](nlohmann::json* j) {
    for (int f = 10; f < 30; ++f) (*j)["frames"][size_t(f)][f % 2 ? "interpolated" : "low_confidence"] = true;
  });
  std::vector<std::string> args = TrainArgs(ws);
  *(std::find(args.begin(), args.end(), "--steps") + 1) = "60";
  args.insert(args.end(), {"--log-level", "info"});
  const Result r = Headforge(args);
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.err.find("20 of 100 training views left out"), std::string::npos) << r.err;
  for (const auto& line : StatsLines(ws / kModelDir / "stats.jsonl"))
    EXPECT_TRUE(std::isfinite(line["loss"].get<double>())) << line;
}

// A time limit that ends training before the deformation's stage says so,
// in the log and in the stage's summary: that avatar does not animate.
TEST(TrainHardCases, ATimeLimitBeforeStageTwoIsSaidAndExtendGoesOnFromThere) {
  const fs::path ws = CopyOf(TrackedTalkingStatic(), Scratch("time_limit"));
  std::vector<std::string> args = TrainArgs(ws);
  *(std::find(args.begin(), args.end(), "--max-minutes") + 1) = "0.0001";  // 6 ms: after the first step
  const Result r = Headforge(args);
  ASSERT_EQ(r.code, 0) << r.err;
  const std::string note = "stage 1 only: the time limit came before stage 2 (step 151)";
  EXPECT_NE(r.err.find("train: " + note), std::string::npos) << r.err;
  EXPECT_NE(Headforge({"status", ws.string()}).out.find(note), std::string::npos);
  for (const auto& line : StatsLines(ws / kModelDir / "stats.jsonl")) {
    if (!line.contains("stage")) continue;
    EXPECT_EQ(line["stage"], 1) << line;
  }

  // The checkpoint where the limit stopped it stays with the model, and
  // --extend with a longer limit goes on from it to the model an
  // uninterrupted run makes; nothing but the limit may change.
  EXPECT_TRUE(fs::exists(ws / kModelDir / "checkpoint.pt"));
  EXPECT_NE(r.err.find("train --extend --max-minutes M goes on"), std::string::npos) << r.err;
  std::vector<std::string> extend = TrainArgs(ws);
  extend.push_back("--extend");
  std::vector<std::string> changed = extend;
  changed.insert(changed.end(), {"--ssim-weight", "0.3"});
  const Result refused = Headforge(changed);
  EXPECT_NE(refused.code, 0);
  EXPECT_NE(refused.err.find("only --max-minutes may change (gaussian_style differ"), std::string::npos)
      << refused.err;
  const Result extended = Headforge(extend);
  ASSERT_EQ(extended.code, 0) << extended.err;
  EXPECT_NE(extended.err.find("going on from the checkpoint"), std::string::npos) << extended.err;
  EXPECT_NE(extended.err.find("resuming from the checkpoint at step 1 "), std::string::npos) << extended.err;
  Result made;
  const fs::path reference = TrainedTalkingStatic(&made);
  ASSERT_EQ(made.code, 0) << made.err;
  EXPECT_EQ(FileHash(ws / kModelDir / "model.pt"), FileHash(reference / kModelDir / "model.pt"));
  EXPECT_FALSE(fs::exists(ws / kModelDir / "checkpoint.pt"));
  // Extending a training that ran to its end: nothing to go on from.
  const Result again = Headforge({"train", "--workspace", ws.string(), "--extend", "--max-minutes", "5"});
  EXPECT_NE(again.code, 0);
  EXPECT_NE(again.err.find("holds no checkpoint to go on from"), std::string::npos) << again.err;
}

// --validation sets the last training frames aside (the held-out frames
// stay as they were) and --patience stops stage 2 once their score stops
// rising; stage 1's scores do not count, since that avatar does not follow
// the expressions.
TEST(TrainHardCases, ValidationFramesChooseWhenStageTwoStops) {
  const fs::path ws = CopyOf(TrackedTalkingStatic(), Scratch("validation"));
  std::vector<std::string> args = TrainArgs(ws);
  *(std::find(args.begin(), args.end(), "--eval-every") + 1) = "10";
  args.insert(args.end(), {"--validation", "0.1", "--patience", "1", "--log-level", "info"});
  const Result r = Headforge(args);
  ASSERT_EQ(r.code, 0) << r.err;
  // 125 frames, the last 25 held out; 10 of the 100 training frames set aside.
  EXPECT_NE(r.err.find("10 training frames (10 views) set aside as validation frames"), std::string::npos) << r.err;
  nlohmann::json eval;
  ASSERT_TRUE(ReadJson(ws / kModelDir / "eval.json", &eval).ok());
  EXPECT_EQ(eval["views"].size(), 25u);
  const nlohmann::json& v = eval.at("validation");
  EXPECT_EQ(v["views"], 10);
  const int stopped = v["stopped_at"].get<int>(), best = v["best_step"].get<int>();
  EXPECT_GT(best, 150) << "stage 1's scores must not count";
  EXPECT_GT(stopped, best);
  EXPECT_LT(stopped, 300) << "with an evaluation every 10 steps and a patience of one, stage 2 stops early";
  EXPECT_NE(r.err.find("stopped at step " + std::to_string(stopped) + " of 300"), std::string::npos) << r.err;
  int evaluations = 0, last_step = 0;
  for (const auto& line : StatsLines(ws / kModelDir / "stats.jsonl")) {
    last_step = std::max(last_step, line.value("step", 0));
    if (!line.contains("validation_psnr_masked")) continue;
    ++evaluations;
    EXPECT_TRUE(std::isfinite(line["validation_psnr_masked"].get<double>())) << line;
  }
  EXPECT_EQ(evaluations, stopped / 10);
  EXPECT_EQ(last_step, stopped);
  EXPECT_NE(Headforge({"status", ws.string()}).out.find("stopped at step " + std::to_string(stopped)),
            std::string::npos);
}

}  // namespace
}  // namespace headforge
