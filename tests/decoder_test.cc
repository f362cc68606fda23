// gaussian-style's stage 3, the StyleGAN decoder, through the train stage:
// its phases, a kill inside it, the same model from a pack trained by
// headforge-train, and the bench's stage-3 variants.
#include "tests/train_fixture.h"

namespace headforge {
namespace {

// Stage 3, the StyleGAN decoder, on a tiny stage 1-2 model: 40 steps at
// 48 px, then a 32 px decoder (prior 20 steps, PTI 10 + 10 on 2 frames,
// 30 fusion steps), a checkpoint every 10 steps.
std::vector<std::string> DecoderArgs(const fs::path& ws) {
  std::vector<std::string> args = TrainArgs(ws);
  *(std::find(args.begin(), args.end(), "--steps") + 1) = "40";
  *(std::find(args.begin(), args.end(), "--checkpoint-every") + 1) = "10";
  args.insert(args.end(), {"--decoder-steps", "30", "--prior-steps", "20", "--pti-steps", "10", "--pti-frames", "2",
                           "--decoder-resolution", "32", "--batch", "2"});
  return args;
}

class DecoderStage : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    reference_ = CopyOf(TrackedTalkingStatic(), Scratch("decoder"));
    first_ = Headforge(DecoderArgs(reference_));
  }
  static fs::path reference_;
  static Result first_;
};
fs::path DecoderStage::reference_;
Result DecoderStage::first_;

TEST_F(DecoderStage, TrainsInFourPhasesAndScoresTheDecodedImageBesideStageTwos) {
  ASSERT_EQ(first_.code, 0) << first_.err;
  const fs::path model = reference_ / kModelDir;
  for (const char* file : {"model.pt", "config.json", "eval.json", "eval_stage2.json"})
    EXPECT_TRUE(fs::exists(model / file)) << file;
  EXPECT_FALSE(fs::exists(model / "decoder_checkpoint.pt"));
  EXPECT_FALSE(fs::exists(model / "checkpoint.pt"));
  // Stats: stage 1-2 lines, then stage 3's phases in order, every loss finite.
  std::vector<std::string> phases;
  std::vector<double> fuse_l1;
  for (const nlohmann::json& line : StatsLines(model / "stats.jsonl")) {
    if (!line.contains("phase")) continue;
    EXPECT_TRUE(std::isfinite(line["loss"].get<double>())) << line;
    const std::string phase = line["phase"];
    if (phases.empty() || phases.back() != phase) phases.push_back(phase);
    if (phase == "fuse") fuse_l1.push_back(line["l1"]);
    // The discriminators' accuracies, which the mode-collapse watch reads.
    if (phase == "prior" || phase == "fuse") {
      EXPECT_GE(line["d_real_accuracy"].get<double>(), 0.0) << line;
      EXPECT_LE(line["d_fake_accuracy"].get<double>(), 1.0) << line;
    }
  }
  EXPECT_EQ(phases, (std::vector<std::string>{"prior", "pti-invert", "pti-tune", "fuse"}));
  ASSERT_EQ(fuse_l1.size(), 3u);
  nlohmann::json config, eval;
  ASSERT_TRUE(ReadJson(model / "config.json", &config).ok());
  ASSERT_TRUE(ReadJson(model / "eval.json", &eval).ok());
  EXPECT_EQ(config["decoder"]["resolution"], 32);
  EXPECT_EQ(config["decoder"]["projected_blocks"], 5);
  EXPECT_TRUE(eval["decoder"].get<bool>());
  EXPECT_EQ(eval["views"].size(), 25u);
  const double decoded = eval["mean"]["psnr_masked"], splatted = eval["stage2"]["psnr_masked"];
  std::printf("held-out PSNR over the head: stage 2 %.2f dB, stage 3 %.2f dB; fusion L1 %.4f -> %.4f\n", splatted,
              decoded, fuse_l1.front(), fuse_l1.back());
  // 30 fusion steps from a 20-step prior: a face-coloured image, not yet stage 2's.
  EXPECT_GT(decoded, 12.0);
  EXPECT_LT(fuse_l1.back(), fuse_l1.front());
  EXPECT_EQ(CountFiles(model / "previews"), 4u);  // each phase's end

  // render draws the decoder's image: the same as the evaluation drew.
  const fs::path out = Scratch("decoder_render");
  const Result r = Headforge({"render", "--workspace", reference_.string(), "--frames", "110", "--out", out.string()});
  ASSERT_EQ(r.code, 0) << r.err;
  const cv::Mat render = cv::imread((out / "frame_000110.png").string());
  const cv::Mat scored = cv::imread((model / "held_out" / "cam0_000110.png").string());
  ASSERT_FALSE(render.empty());
  ASSERT_EQ(scored.cols, 3 * render.cols);
  EXPECT_LE(cv::norm(render, scored(cv::Rect(0, 0, render.cols, render.rows)), cv::NORM_INF), 1.0);
}

TEST_F(DecoderStage, KilledInStageThreeResumesThereToTheSameModel) {
  ASSERT_EQ(first_.code, 0) << first_.err;
  const fs::path ws = CopyOf(TrackedTalkingStatic(), Scratch("decoder_killed"));
  const fs::path log = fs::temp_directory_path() / "hf_train_decoder_killed.log";
  const fs::path staging = ws / ".staging" / "train" / kModelDir;
  // Stage 1-2 log 4 lines; kill once stage 3 has logged three (step 30, PTI).
  ASSERT_TRUE(KillTrainingMidway(DecoderArgs(ws), staging, 7, log, "decoder_checkpoint.pt"));
  // Stage 3's checkpoint replaced stages 1-2's.
  EXPECT_FALSE(fs::exists(staging / "checkpoint.pt"));

  const Result resumed = Headforge(DecoderArgs(ws));
  ASSERT_EQ(resumed.code, 0) << resumed.err;
  EXPECT_NE(resumed.err.find("resuming stage 3 from its checkpoint at step"), std::string::npos) << resumed.err;
  EXPECT_EQ(resumed.err.find("gaussian-style: started"), std::string::npos) << "stages 1-2 ran again";
  EXPECT_EQ(FileHash(ws / kModelDir / "model.pt"), FileHash(reference_ / kModelDir / "model.pt"));
  const std::vector<nlohmann::json> stats = StatsLines(ws / kModelDir / "stats.jsonl");
  const std::vector<nlohmann::json> expected = StatsLines(reference_ / kModelDir / "stats.jsonl");
  ASSERT_EQ(stats.size(), expected.size());
  for (size_t i = 0; i < stats.size(); ++i) EXPECT_EQ(stats[i]["loss"], expected[i]["loss"]) << i;
}

// A training pack (headforge pack) trained by headforge-train, the
// LibTorch-only program for GPU machines: the same model, losses and scores
// as headforge train on the workspace, stage 3 included; and the folder it
// writes renders in the workspace as the train stage's does.
TEST_F(DecoderStage, APackTrainedByHeadforgeTrainGivesTheSameModelAsTheTrainStage) {
  ASSERT_EQ(first_.code, 0) << first_.err;
  const fs::path ws = CopyOf(TrackedTalkingStatic(), Scratch("pack"));
  std::vector<std::string> args = DecoderArgs(ws);
  args[0] = "pack";
  args.insert(args.end(), {"--out", (ws / "talking.pack").string()});
  const Result packed = Headforge(args);
  ASSERT_EQ(packed.code, 0) << packed.err;
  EXPECT_NE(packed.err.find("headforge-train"), std::string::npos) << packed.err;
  const fs::path out = ws / "trained_elsewhere";
  const Result trained =
      Headforge({(ws / "talking.pack").string(), "--out", out.string(), "--threads", "1"}, HEADFORGE_TRAIN_BINARY);
  ASSERT_EQ(trained.code, 0) << trained.err;
  EXPECT_EQ(FileHash(out / "model.pt"), FileHash(reference_ / kModelDir / "model.pt"));
  const std::vector<nlohmann::json> stats = StatsLines(out / "stats.jsonl");
  const std::vector<nlohmann::json> expected = StatsLines(reference_ / kModelDir / "stats.jsonl");
  ASSERT_EQ(stats.size(), expected.size());
  for (size_t i = 0; i < stats.size(); ++i) EXPECT_EQ(stats[i]["loss"], expected[i]["loss"]) << i;
  nlohmann::json eval, expected_eval;
  ASSERT_TRUE(ReadJson(out / "eval.json", &eval).ok());
  ASSERT_TRUE(ReadJson(reference_ / kModelDir / "eval.json", &expected_eval).ok());
  EXPECT_EQ(eval["mean"], expected_eval["mean"]);

  // Copied into the workspace, the model renders there.
  fs::create_directories(ws / "models");
  fs::rename(out, ws / kModelDir);
  const Result r = Headforge({"render", "--workspace", ws.string(), "--frames", "110", "--out",
                              (ws / "renders").string()});
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(fs::exists(ws / "renders" / "frame_000110.png"));
}

// `bench train`'s stage-3 variants (the paper's Table 2b): each trains the
// same stages 1-2 and its own stage 3, and its row sets stage 2's figures
// beside the decoded image's.
TEST_F(DecoderStage, TheBenchsStageThreeVariantsScoreStageTwoBesideTheDecodedImage) {
  ASSERT_EQ(first_.code, 0) << first_.err;
  const fs::path ws = CopyOf(TrackedTalkingStatic(), Scratch("bench_stage3"));
  std::vector<std::string> args = DecoderArgs(ws);
  args[0] = "bench";
  args.insert(args.begin() + 1, "train");
  args.insert(args.end(), {"--variants", "stage3,stage3-no-discriminator", "--json"});
  const Result bench = Headforge(args);
  ASSERT_EQ(bench.code, 0) << bench.err;
  const nlohmann::json rows = nlohmann::json::parse(bench.out).at("variants");
  ASSERT_EQ(rows.size(), 2u);
  nlohmann::json eval;
  ASSERT_TRUE(ReadJson(reference_ / kModelDir / "eval.json", &eval).ok());
  for (const nlohmann::json& row : rows) {
    ASSERT_TRUE(row.contains("stage2")) << row;
    // Stages 1-2 are the train stage's with these options, to the digit.
    EXPECT_EQ(row["stage2"]["psnr_masked"], eval["stage2"]["psnr_masked"]) << row["variant"];
    EXPECT_EQ(row["stage2"]["sd"], eval["stage2"]["sd"]) << row["variant"];
    EXPECT_GT(row["stage3_seconds"].get<double>(), 0);
    EXPECT_GT(row["render_ms"].get<double>(), 0);
  }
  // The full variant is the train stage's run; without the discriminator, stage 3 differs.
  EXPECT_EQ(rows[0]["what"], "stages 1-3");
  EXPECT_EQ(rows[0]["psnr_masked"], eval["mean"]["psnr_masked"]);
  EXPECT_EQ(rows[0]["sd"], eval["mean"]["sd"]);
  EXPECT_NE(rows[1]["psnr_masked"], rows[0]["psnr_masked"]);
  // A stage-3 variant without --decoder-steps is refused before anything trains.
  const Result refused = Headforge({"bench", "train", "--workspace", ws.string(), "--variants", "stage3-no-ada"});
  EXPECT_EQ(refused.code, 2);
  EXPECT_NE(refused.err.find("stage 3 needs --decoder-steps"), std::string::npos) << refused.err;
}

// --model auto: the model follows from the aligned cameras.

}  // namespace
}  // namespace headforge
