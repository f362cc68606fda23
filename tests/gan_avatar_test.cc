// The gan-avatar model through `headforge train` on the small simulated
// capture train_test uses (talking_static, tracked once and shared), at a
// 16 px volume render super-resolved to 32 px, tens of steps: it trains,
// tracks its own renders and maps expressions to latents, writes its model,
// every loss in stats.jsonl is finite, the same seed gives the same model,
// and a run killed outright resumes from its checkpoint to the model an
// uninterrupted run makes.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <sstream>
#include <thread>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "core/fs.h"
#include "core/json_io.h"
#include "tests/run_headforge.h"
#include "tests/shared_workspace.h"

namespace headforge {
namespace {

const char* const kModelDir = "models/gan_avatar";

fs::path Scratch(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("hf_gan_" + name);
  fs::remove_all(dir);
  return dir;
}

std::vector<std::string> TrainArgs(const fs::path& ws) {
  return {"train", "--workspace", ws.string(), "--model", "gan-avatar", "--train-size", "32",
          "--render-resolution", "16", "--samples", "8", "--fine-samples", "8", "--batch", "2",
          "--triplane-resolution", "16", "--steps", "40", "--log-every", "5", "--checkpoint-every", "5",
          "--r1-every", "2", "--eval-every", "0", "--preview-every", "20", "--max-minutes", "0", "--threads", "1",
          "--mapping-samples", "24", "--mapping-steps", "10", "--reconstruction-steps", "20"};
}

class GanAvatarTrain : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    reference_ = CopyOf(TrackedTalkingStatic(), Scratch("reference"));
    first_ = Headforge(TrainArgs(reference_));
  }
  static fs::path reference_;
  static Result first_;
};
fs::path GanAvatarTrain::reference_;
Result GanAvatarTrain::first_;

TEST_F(GanAvatarTrain, TrainsAndWritesItsModel) {
  ASSERT_EQ(first_.code, 0) << first_.err;
  const fs::path model = reference_ / kModelDir;
  for (const char* file : {"model.pt", "config.json", "stats.jsonl", "eval.json"})
    EXPECT_TRUE(fs::exists(model / file)) << file;
  EXPECT_EQ(CountFiles(model / "previews"), 2u);  // steps 20 and 40
  std::vector<nlohmann::json> stats = StatsLines(model / "stats.jsonl");
  ASSERT_EQ(stats.size(), 10u);  // a line every 5 steps, then two of the mapping's
  std::vector<nlohmann::json> mapping(stats.end() - 2, stats.end());
  stats.resize(8);
  EXPECT_EQ(mapping[0]["mapping_step"], 5);
  EXPECT_EQ(mapping[1]["mapping_step"], 10);
  for (const auto& line : mapping) EXPECT_TRUE(std::isfinite(line["mapping_loss"].get<double>())) << line;
  // Four lines of the reconstruction warm-up (steps 1-20), then the GAN's.
  EXPECT_EQ(stats[3]["phase"], "reconstruction");
  EXPECT_EQ(stats[4]["phase"], "adversarial");
  EXPECT_GT(stats[0]["recon_l1"].get<double>(), stats[3]["recon_l1"].get<double>());  // it learns
  double r1 = 0;
  for (const auto& line : stats) {
    for (const char* key : {"loss_g", "loss_d", "r1", "d_real_accuracy", "d_fake_accuracy", "augment_p"})
      EXPECT_TRUE(line.contains(key) && std::isfinite(line[key].get<double>())) << key << " in " << line;
    EXPECT_GE(line["augment_p"].get<double>(), 0);
    EXPECT_LE(line["augment_p"].get<double>(), 1);
    r1 += line["r1"].get<double>();
  }
  EXPECT_GT(r1, 0);  // the penalty ran
  nlohmann::json config, eval;
  ASSERT_TRUE(ReadJson(model / "config.json", &config).ok());
  EXPECT_EQ(config["model"], "gan-avatar");
  EXPECT_EQ(config["architecture"]["super_resolution_doublings"], 1);
  EXPECT_EQ(config["output_size"][0], 32);
  // The head's box holds the tracked head: about 0.2-0.4 m a side.
  for (int a = 0; a < 3; ++a) {
    const double side = config["architecture"]["box_max"][a].get<double>() - config["architecture"]["box_min"][a].get<double>();
    EXPECT_GT(side, 0.15) << a;
    EXPECT_LT(side, 0.6) << a;
  }
  ASSERT_TRUE(ReadJson(model / "eval.json", &eval).ok());
  EXPECT_EQ(eval["views"].size(), 25u);
  EXPECT_EQ(CountFiles(model / "held_out"), 25u);
  EXPECT_TRUE(std::isfinite(eval["mean"]["psnr_masked"].get<double>()));
  // The held-out frames are driven through the mapping; the renders it
  // learnt from were tracked (garbage at 40 steps, but each one fitted).
  EXPECT_NE(eval["latent"].get<std::string>().find("expression mapping"), std::string::npos) << eval["latent"];
  EXPECT_EQ(eval["mapping"]["renders"], 24);
  EXPECT_EQ(eval["mapping"]["tracked"], 24);
  EXPECT_EQ(eval["mapping"]["latents"], "random");  // the default, the paper's
  EXPECT_TRUE(std::isfinite(eval["mean_latent"]["psnr_masked"].get<double>()));
  // Then 24 of the capture's frames (as many as the mapping's renders) drive
  // it, their renders read back beside the mean latent's and the frames'.
  const nlohmann::json agreement = eval["expression_agreement"];
  EXPECT_EQ(agreement["of"], 24) << agreement;
  EXPECT_GE(agreement["frames"].get<int>(), 2) << agreement;
  for (const char* key : {"error", "mean_latent_error", "frames_error"})
    EXPECT_TRUE(std::isfinite(agreement[key].get<double>())) << key << agreement;
  EXPECT_EQ(agreement["blendshapes"].size(), std::min(5, agreement["readable_blendshapes"].get<int>())) << agreement;
  for (const auto& b : agreement["blendshapes"]) EXPECT_GE(b["frames_correlation"].get<double>(), 0.5) << b;
  EXPECT_NE(first_.err.find("read back within"), std::string::npos) << first_.err;
  EXPECT_TRUE(config["expression_mapping"]["trained"].get<bool>());
  EXPECT_EQ(config["expression_mapping"]["expressions"].size(), 53u);
  EXPECT_NE(first_.err.find("train: gan-avatar"), std::string::npos) << first_.err;
}

// The same seed's model again is the pack test's (the GAN trained by
// headforge-train and the mapping added on the workspace give the
// reference's model.pt) and the kill test's; another seed gives another.
TEST_F(GanAvatarTrain, AnotherSeedGivesAnotherModel) {
  ASSERT_EQ(first_.code, 0) << first_.err;
  const fs::path other = CopyOf(TrackedTalkingStatic(), Scratch("other_seed"));
  std::vector<std::string> args = TrainArgs(other);
  args.insert(args.end(), {"--train-seed", "3"});
  const Result r = Headforge(args);
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(FileHash(other / kModelDir / "model.pt"), FileHash(reference_ / kModelDir / "model.pt"));
}

TEST_F(GanAvatarTrain, KilledMidTrainingResumesToTheSameModel) {
  ASSERT_EQ(first_.code, 0) << first_.err;
  const fs::path ws = CopyOf(TrackedTalkingStatic(), Scratch("killed"));
  const fs::path log = Scratch("killed.log");
  // Killed without warning once a checkpoint past step 15 exists.
  ASSERT_TRUE(KillTrainingMidway(TrainArgs(ws), ws / ".staging" / "train" / kModelDir, 3, log));
  EXPECT_FALSE(fs::exists(ws / kModelDir / "model.pt"));

  const Result resumed = Headforge(TrainArgs(ws));
  ASSERT_EQ(resumed.code, 0) << resumed.err;
  EXPECT_NE(resumed.err.find("resuming from the checkpoint at step"), std::string::npos) << resumed.err;
  EXPECT_EQ(FileHash(ws / kModelDir / "model.pt"), FileHash(reference_ / kModelDir / "model.pt"));
  // stats.jsonl has the reference's lines, losses and all (only the times differ).
  std::vector<nlohmann::json> stats = StatsLines(ws / kModelDir / "stats.jsonl");
  std::vector<nlohmann::json> expected = StatsLines(reference_ / kModelDir / "stats.jsonl");
  ASSERT_EQ(stats.size(), expected.size());
  for (size_t i = 0; i < stats.size(); ++i) {
    stats[i].erase("seconds");
    expected[i].erase("seconds");
    EXPECT_EQ(stats[i], expected[i]) << i;
  }
}

// The GPU machine's route: a training pack of the gan-avatar model trained
// by headforge-train (the LibTorch-only program) gives the train stage's GAN
// without an expression mapping (the mean latent draws every frame); then
// `headforge train --generator-from` on the workspace adds the mapping,
// trains no GAN, and makes the train stage's model.
TEST_F(GanAvatarTrain, APackTrainsTheGanAndTheWorkspaceAddsTheMapping) {
  ASSERT_EQ(first_.code, 0) << first_.err;
  const fs::path ws = CopyOf(TrackedTalkingStatic(), Scratch("pack"));
  std::vector<std::string> args = TrainArgs(ws);
  args[0] = "pack";
  args.insert(args.end(), {"--out", (ws / "gan.pack").string()});
  const Result packed = Headforge(args);
  ASSERT_EQ(packed.code, 0) << packed.err;
  const fs::path out = ws / "trained_elsewhere";
  const Result trained =
      Headforge({(ws / "gan.pack").string(), "--out", out.string(), "--threads", "1"}, HEADFORGE_TRAIN_BINARY);
  ASSERT_EQ(trained.code, 0) << trained.err;
  EXPECT_NE(trained.err.find("--generator-from"), std::string::npos) << trained.err;
  nlohmann::json config, eval, expected_eval;
  ASSERT_TRUE(ReadJson(out / "config.json", &config).ok());
  EXPECT_FALSE(config["expression_mapping"]["trained"].get<bool>());
  EXPECT_EQ(config["options"]["data"]["resolution"], 32);
  ASSERT_TRUE(ReadJson(out / "eval.json", &eval).ok());
  ASSERT_TRUE(ReadJson(reference_ / kModelDir / "eval.json", &expected_eval).ok());
  EXPECT_NE(eval["latent"].get<std::string>().find("running mean"), std::string::npos) << eval["latent"];
  // The GAN is the train stage's: the same losses at every logged step, and
  // the same held-out scores for the mean latent.
  std::vector<nlohmann::json> gan = StatsLines(out / "stats.jsonl");
  const std::vector<nlohmann::json> expected = StatsLines(reference_ / kModelDir / "stats.jsonl");
  ASSERT_EQ(gan.size(), 8u);
  for (size_t i = 0; i < gan.size(); ++i) EXPECT_EQ(gan[i]["loss_g"], expected[i]["loss_g"]) << i;
  EXPECT_EQ(eval["mean"]["psnr_masked"], expected_eval["mean_latent"]["psnr_masked"]);

  // On the workspace: the mapping alone, to the train stage's model.
  args = TrainArgs(ws);
  args.insert(args.end(), {"--generator-from", out.string()});
  const Result mapped = Headforge(args);
  ASSERT_EQ(mapped.code, 0) << mapped.err;
  EXPECT_NE(mapped.err.find("training the expression mapping only"), std::string::npos) << mapped.err;
  EXPECT_EQ(mapped.err.find("adversarial training from step"), std::string::npos) << "the GAN trained again";
  EXPECT_EQ(FileHash(ws / kModelDir / "model.pt"), FileHash(reference_ / kModelDir / "model.pt"));
  ASSERT_TRUE(ReadJson(ws / kModelDir / "eval.json", &eval).ok());
  EXPECT_EQ(eval["mean"], expected_eval["mean"]);
  const std::vector<nlohmann::json> whole = StatsLines(ws / kModelDir / "stats.jsonl");
  ASSERT_EQ(whole.size(), expected.size());  // the GAN's lines, then the mapping's
  EXPECT_EQ(whole.back()["mapping_loss"], expected.back()["mapping_loss"]);

  // A folder that holds no gan-avatar training is refused before anything loads.
  args = TrainArgs(ws);
  args.insert(args.end(), {"--generator-from", (ws / "nothing").string()});
  const Result refused = Headforge(args);
  EXPECT_EQ(refused.code, 1);
  EXPECT_NE(refused.err.find("--generator-from"), std::string::npos) << refused.err;
}

TEST_F(GanAvatarTrain, TheLatentLossAblationMapsToo) {
  ASSERT_EQ(first_.code, 0) << first_.err;
  // The mapping trained on the reference's GAN (the loss changes the mapping
  // alone; the GAN's own training is the reference's, tested above).
  const fs::path ws = CopyOf(TrackedTalkingStatic(), Scratch("latent"));
  std::vector<std::string> args = TrainArgs(ws);
  args.insert(args.end(), {"--generator-from", (reference_ / kModelDir).string(), "--mapping-loss", "latent"});
  const Result r = Headforge(args);
  ASSERT_EQ(r.code, 0) << r.err;
  const std::vector<nlohmann::json> stats = StatsLines(ws / kModelDir / "stats.jsonl");
  ASSERT_GE(stats.size(), 1u);
  EXPECT_EQ(stats.back()["mapping_loss_kind"], "latent");
  // The reference's GAN: only the mapping differs.
  nlohmann::json a, b;
  ASSERT_TRUE(ReadJson(ws / kModelDir / "eval.json", &a).ok());
  ASSERT_TRUE(ReadJson(reference_ / kModelDir / "eval.json", &b).ok());
  EXPECT_EQ(a["mean_latent"]["psnr_masked"], b["mean_latent"]["psnr_masked"]);
  EXPECT_EQ(a["mapping"]["loss"], "latent");

  // The mapping alone again, from the warm-up's latents of the training
  // frames (the model keeps them): 24 of the 100 training frames are rendered.
  const fs::path frames = CopyOf(TrackedTalkingStatic(), Scratch("frame_latents"));
  args = TrainArgs(frames);
  args.insert(args.end(), {"--generator-from", (reference_ / kModelDir).string(), "--mapping-latents", "frames"});
  const Result f = Headforge(args);
  ASSERT_EQ(f.code, 0) << f.err;
  EXPECT_NE(f.err.find("latents of 24 of the 100 training frames"), std::string::npos) << f.err;
  nlohmann::json c;
  ASSERT_TRUE(ReadJson(frames / kModelDir / "eval.json", &c).ok());
  EXPECT_EQ(c["mapping"]["latents"], "frames");
  EXPECT_EQ(c["mapping"]["tracked"], 24);
  EXPECT_EQ(c["mean_latent"]["psnr_masked"], b["mean_latent"]["psnr_masked"]);  // the same GAN
  args.back() = "sideways";
  const Result wrong = Headforge(args);
  EXPECT_EQ(wrong.code, 2);  // the command line
  EXPECT_NE(wrong.err.find("--mapping-latents must be random or frames"), std::string::npos) << wrong.err;
}

TEST_F(GanAvatarTrain, RenderDrawsItFromTurnedCamerasAndDrivenByAnotherCapture) {
  ASSERT_EQ(first_.code, 0) << first_.err;
  const fs::path ws = CopyOf(reference_, Scratch("render"));
  auto render = [&](std::vector<std::string> extra, const std::string& name = "frame_000100.png") {
    std::vector<std::string> args = {"render", "--workspace", ws.string(), "--frames", "100"};
    args.insert(args.end(), extra.begin(), extra.end());
    const Result r = Headforge(args);
    EXPECT_EQ(r.code, 0) << r.err;
    // The one render, named for what it drew (frame_000100.png, _yaw+40_pitch+0, _driven).
    std::vector<std::string> files;
    for (const auto& entry : fs::directory_iterator(ws / "renders")) files.push_back(entry.path().filename());
    EXPECT_EQ(files, std::vector<std::string>{name}) << name;
    const cv::Mat image = cv::imread((ws / "renders" / name).string());
    fs::remove_all(ws / "renders");
    return image;
  };
  const cv::Mat front = render({}), turned = render({"--yaw", "40"}, "frame_000100_yaw+40_pitch+0.png");
  ASSERT_FALSE(front.empty());
  EXPECT_EQ(front.cols, 32);  // the model's output size
  EXPECT_EQ(front.rows, 32);
  EXPECT_GT(cv::norm(front, turned, cv::NORM_L1), 0);  // the camera moved
  const cv::Mat again = render({});
  EXPECT_EQ(cv::norm(front, again, cv::NORM_L1), 0);  // the same frame, the same image
  // Driven by another tracked capture's expressions (here the same capture
  // through its shared workspace: its frame 100 has this frame's expression).
  const cv::Mat driven = render({"--drive", TrackedTalkingStatic().string()}, "frame_000100_driven.png");
  ASSERT_FALSE(driven.empty());
  EXPECT_EQ(driven.size(), front.size());
  // The held-out frames side by side with the frames: render | frame | error.
  const Result strip = Headforge({"render", "--workspace", ws.string(), "--held-out", "--side-by-side"});
  ASSERT_EQ(strip.code, 0) << strip.err;
  EXPECT_EQ(CountFiles(ws / "renders"), 25u);
  EXPECT_EQ(cv::imread((ws / "renders" / "frame_000110_side_by_side.png").string()).cols, 96);
}

// Export of a workspace whose only model is gan-avatar: the mesh avatar and
// the report, the model's weights (which render the same image as the
// trained folder) and its videos; no Gaussians (nor a clip of them), which
// it does not have.
TEST_F(GanAvatarTrain, ExportWritesTheModelsWeightsAndVideosAndNoGaussians) {
  ASSERT_EQ(first_.code, 0) << first_.err;
  const fs::path ws = CopyOf(reference_, Scratch("export"));
  const Result r = Headforge({"export", "--workspace", ws.string(), "--texture-size", "64", "--bake-views", "4"});
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.err.find("no gaussians.ply"), std::string::npos) << r.err;
  const fs::path out = ws / "export";
  for (const char* file : {"avatar_mesh.glb", "report.html", "weights/weights.safetensors", "weights/config.json",
                           "videos/self_reenactment.mp4", "videos/orbit.mp4"})
    EXPECT_TRUE(fs::exists(out / file)) << file;
  EXPECT_FALSE(fs::exists(out / "gaussians.glb"));
  nlohmann::json config;
  ASSERT_TRUE(ReadJson(out / "weights" / "config.json", &config).ok());
  EXPECT_EQ(config["model"], "gan-avatar");
  EXPECT_TRUE(config.contains("identity"));
  // The exported weights draw what the trained folder draws.
  const auto render = [&](const fs::path& model, const std::string& into) {
    const Result rendered = Headforge({"render", "--workspace", ws.string(), "--frames", "110", "--model",
                                       model.string(), "--out", (ws / into).string()});
    EXPECT_EQ(rendered.code, 0) << rendered.err;
    return Slurp(ws / into / "frame_000110.png");
  };
  const std::string trained = render(ws / "models" / "gan_avatar", "from_trained");
  ASSERT_FALSE(trained.empty());
  EXPECT_EQ(render(out / "weights", "from_export"), trained);
  // Asking for Gaussians alone from it is refused.
  const Result gaussians = Headforge({"export", "--workspace", ws.string(), "--formats", "gaussians"});
  EXPECT_EQ(gaussians.code, 2);
  EXPECT_NE(gaussians.err.find("has no Gaussians"), std::string::npos) << gaussians.err;
  // And so is a baked clip of Gaussians.
  const Result clip = Headforge({"export", "--workspace", ws.string(), "--formats", "report", "--frames", "0-9"});
  EXPECT_EQ(clip.code, 2);
  EXPECT_NE(clip.err.find("--frames bakes the Gaussian avatar's clip"), std::string::npos) << clip.err;
}

TEST(GanAvatarOptions, ARenderSizeThatDoesNotDivideTheOutputIsRefused) {
  const fs::path ws = CopyOf(TrackedTalkingStatic(), Scratch("bad_options"));
  const Result r = Headforge({"train", "--workspace", ws.string(), "--model", "gan-avatar", "--train-size", "64",
                              "--render-resolution", "24"});
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.err.find("--render-resolution must divide --train-size by a power of two"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(ws / kModelDir / "model.pt"));
  // The frames' latents asked of a GAN that would fit none: refused before
  // any training, not after it.
  const Result no_codes =
      Headforge({"train", "--workspace", ws.string(), "--model", "gan-avatar", "--mapping-latents", "frames",
                 "--reconstruction-steps", "0", "--recon-weight", "0"});
  EXPECT_EQ(no_codes.code, 2);
  EXPECT_NE(no_codes.err.find("use --mapping-latents random"), std::string::npos) << no_codes.err;
  EXPECT_FALSE(fs::exists(ws / kModelDir / "model.pt"));
}

}  // namespace
}  // namespace headforge
