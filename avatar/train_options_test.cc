// train's options in JSON (a training pack's record, a model's
// config.json): the blocks written go back to the same options, and the flat
// record of earlier versions (every field at the top) still reads.
#include <fstream>

#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "avatar/avatar_train.h"
#include "avatar/model_table.h"

namespace headforge {
namespace {

// Every option as ToJson wrote them before the blocks (one flat object, keys
// in nlohmann's order), with values besides the defaults in each block.
constexpr const char* kFlatRecord = R"json({
      "ada_target": 0.6, "adversarial_ramp": 300, "adversarial_weight": 0.05, "batch": 2,
      "canonical_fraction": 0.5, "checkpoint_every": 10, "coarse_samples": 24, "collapse_steps": 200,
      "decoder_ada": false, "decoder_init": "g.safetensors", "decoder_max_minutes": 1.5,
      "decoder_resolution": 0, "decoder_steps": 100, "deform": true, "densify_every": 100, "densify_from": 300,
      "densify_until": 3000, "device": "cuda", "eval_every": 0, "feature_channels": 32, "fine_samples": 24,
      "full_tune": false, "generator_from": "gan_dir", "grad_threshold": 0.0002, "holdout": 0.25,
      "holdout_cameras": ["side"], "holdout_order": "interleaved", "init_gaussians": 20000,
      "landmark_model": "", "latent_dim": 64, "latent_dropout": 0.0, "log_every": 50, "lr_discriminator": 0.002,
      "lr_features": 0.0025, "lr_means": 0.00016, "lr_network": 0.25, "lr_opacity": 0.05, "lr_quats": 0.001,
      "lr_scales": 0.005, "mapping_latents": "frames", "mapping_loss": "image", "mapping_samples": 256,
      "mapping_steps": 300, "mask": "mesh", "mask_hair": 0.05, "mask_skin": 0.016, "max_gaussians": 50000,
      "max_minutes": 2.5, "mesh_riding": false, "model": "gaussian-style", "patience": 3,
      "perceptual_weight": 0.1, "pose_lr": 0.0, "preset": "standard", "preview_every": 1000,
      "prior_steps": 1000, "projected_blocks": 5, "pti_frames": 4, "pti_steps": 200, "r1_every": 4,
      "r1_gamma": 0.5, "recon_weight": 1.0, "reconstruction_steps": 0, "region_weight": 1.0,
      "render_resolution": 64, "resolution": 128, "seed": 7, "ssim_weight": 0.2, "steps": 1234,
      "triplane_resolution": 64, "validation": 0.1})json";

TEST(TrainOptionsJson, TheFlatRecordOfEarlierVersionsReadsIntoEachBlock) {
  const TrainOptions o = TrainOptionsFromJson(nlohmann::json::parse(kFlatRecord));
  EXPECT_EQ(o.model, "gaussian-style");
  EXPECT_EQ(o.preset, "standard");
  EXPECT_EQ(o.device, "cuda");
  EXPECT_EQ(o.seed, 7);
  EXPECT_EQ(o.lr_network, 0.25);
  EXPECT_EQ(o.batch, 2);
  EXPECT_EQ(o.r1_gamma, 0.5);
  EXPECT_EQ(o.lr_discriminator, 0.002);
  EXPECT_EQ(o.data.resolution, 128);
  EXPECT_EQ(o.data.holdout, 0.25);
  EXPECT_EQ(o.data.holdout_order, "interleaved");
  EXPECT_EQ(o.data.holdout_cameras, std::vector<std::string>{"side"});
  EXPECT_EQ(o.data.mask, "mesh");
  EXPECT_EQ(o.data.mask_hair, 0.05);
  EXPECT_EQ(o.data.mask_skin, 0.016);
  EXPECT_EQ(o.loop.steps, 1234);
  EXPECT_EQ(o.loop.max_minutes, 2.5);
  EXPECT_EQ(o.loop.eval_every, 0);
  EXPECT_EQ(o.loop.checkpoint_every, 10);
  EXPECT_EQ(o.loop.log_every, 50);
  const GaussianStyleTrainOptions& g = o.gaussian_style;
  EXPECT_EQ(g.canonical_fraction, 0.5);
  EXPECT_FALSE(g.mesh_riding);
  EXPECT_TRUE(g.deform);
  EXPECT_EQ(g.validation, 0.1);
  EXPECT_EQ(g.patience, 3);
  EXPECT_EQ(g.max_gaussians, 50000);
  EXPECT_EQ(g.lr_means, 0.00016);
  EXPECT_EQ(g.decoder.decoder_steps, 100);
  EXPECT_EQ(g.decoder.decoder_max_minutes, 1.5);
  EXPECT_FALSE(g.decoder.decoder_ada);
  EXPECT_EQ(g.decoder.decoder_init, "g.safetensors");
  EXPECT_EQ(g.decoder.prior_steps, 1000);
  EXPECT_EQ(o.gan_avatar.render_resolution, 64);
  EXPECT_EQ(o.gan_avatar.mapping_latents, "frames");
  EXPECT_EQ(o.gan_avatar.generator_from, "gan_dir");
  EXPECT_EQ(o.gan_avatar.mapping_steps, 300);
}

TEST(TrainOptionsJson, TheBlocksReadBackAsWritten) {
  const nlohmann::json flat = nlohmann::json::parse(kFlatRecord);
  for (const AvatarModel& model : kAvatarModels) {
    nlohmann::json record = flat;
    record["model"] = model.Name();
    const TrainOptions options = TrainOptionsFromJson(record);
    const nlohmann::json blocks = ToJson(options);
    // The common part at the top, each block once, the trained model's alone.
    for (const char* block : {"data", "loop"}) EXPECT_TRUE(blocks.at(block).is_object()) << block;
    EXPECT_EQ(blocks.contains("gaussian_style"), kGaussianStyle.Is(model.name)) << model.name;
    EXPECT_EQ(blocks.contains("gan_avatar"), kGanAvatar.Is(model.name)) << model.name;
    EXPECT_FALSE(blocks.contains("resolution"));
    EXPECT_EQ(blocks.at("data").at("resolution"), 128);
    EXPECT_EQ(blocks.at("seed"), 7);
    EXPECT_EQ(ToJson(TrainOptionsFromJson(blocks)), blocks) << model.name;
  }
  const nlohmann::json style = ToJson(TrainOptionsFromJson(flat)).at("gaussian_style");
  EXPECT_EQ(style.at("decoder").at("decoder_init"), "g.safetensors");
  EXPECT_FALSE(style.contains("decoder_init"));
}

// A field the record lacks keeps its default: train's mask is auto (each
// model's own), not the loader's.
TEST(TrainOptionsJson, AFieldTheRecordLacksKeepsItsDefault) {
  const TrainOptions defaults;
  for (const char* text : {R"({"model": "gan-avatar"})", R"({"model": "gan-avatar", "data": {}, "loop": {}})"}) {
    const TrainOptions o = TrainOptionsFromJson(nlohmann::json::parse(text));
    EXPECT_EQ(o.model, "gan-avatar");
    EXPECT_EQ(o.data.mask, "auto") << text;
    EXPECT_EQ(o.data.holdout_order, "auto") << text;
    EXPECT_EQ(o.data.resolution, defaults.data.resolution) << text;
    EXPECT_EQ(o.loop.steps, defaults.loop.steps) << text;
    EXPECT_EQ(o.gan_avatar.render_resolution, defaults.gan_avatar.render_resolution) << text;
    EXPECT_EQ(o.gaussian_style.decoder.prior_steps, defaults.gaussian_style.decoder.prior_steps) << text;
  }
}

// The model table's two kinds: what train trains and what export makes.
TEST(ModelTable, TrainedAndExportedModelsHaveTheirOwnFolders) {
  const fs::path ws = "/data/ws";
  EXPECT_EQ(kGaussianStyle.Dir(ws), ws / "models" / "gaussian_style");
  EXPECT_EQ(kGaussianBlendshapes.Dir(ws), ws / "export" / "blendshapes");
  EXPECT_TRUE(kGanAvatar.Trained());
  EXPECT_FALSE(kGaussianBlendshapes.Trained());
  EXPECT_EQ(FindAvatarModel("gaussian-blendshapes"), nullptr);  // train does not offer it
  EXPECT_EQ(FindAnyAvatarModel("gaussian-blendshapes"), &kExportedModels[0]);
  EXPECT_EQ(FindAnyAvatarModel("gan-avatar"), &kAvatarModels[1]);
  EXPECT_EQ(FindAnyAvatarModel("blendshapes"), nullptr);  // a folder's name is not a model's
  EXPECT_EQ(AvatarModelNames(), "gaussian-style or gan-avatar");
  EXPECT_EQ(AvatarModelNames(true), "gaussian-style, gan-avatar or gaussian-blendshapes");
  EXPECT_EQ(kGaussianBlendshapes.MadeBy(ws), "headforge export --workspace /data/ws --formats blendshapes");
  EXPECT_EQ(kGanAvatar.MadeBy(ws), "headforge train --workspace /data/ws --model gan-avatar");
  EXPECT_EQ(kGaussianBlendshapes.made_from, kGaussianStyle.name);
  // A model is in a workspace when its marker file is.
  const fs::path tmp = fs::temp_directory_path() / "hf_model_table_test";
  fs::remove_all(tmp);
  fs::create_directories(kGaussianBlendshapes.Dir(tmp));
  EXPECT_FALSE(kGaussianBlendshapes.In(tmp));
  std::ofstream(kGaussianBlendshapes.Dir(tmp) / "blendshapes.json") << "{}";
  EXPECT_TRUE(kGaussianBlendshapes.In(tmp));
  EXPECT_FALSE(kGaussianStyle.In(tmp));
  fs::remove_all(tmp);
  // train refuses the exported one, saying what makes it.
  TrainOptions options;
  options.model = "gaussian-blendshapes";
  const Status s = options.Check();
  EXPECT_EQ(s.code(), Status::Code::kInvalidArgument);
  EXPECT_NE(s.message().find("export --formats blendshapes"), std::string::npos) << s.message();
}

// The hold-out's split: the last frames, or interleaved from the middle of
// the first stride; HeldOutFrames counts what it holds out.
TEST(HoldoutSplit, HoldsOutTheLastFramesOrEveryStrideth) {
  const HoldoutSplit last = SplitFrames(75, 0.2, false);
  EXPECT_EQ(last.first_test_frame, 60);
  EXPECT_FALSE(last.HeldOut(59));
  EXPECT_TRUE(last.HeldOut(60));
  EXPECT_TRUE(last.HeldOut(74));
  const HoldoutSplit every = SplitFrames(12, 0.2, true);  // a stride of 5: frames 2, 7
  EXPECT_EQ(every.every, 5);
  std::vector<int> held;
  for (int f = 0; f < 12; ++f)
    if (every.HeldOut(f)) held.push_back(f);
  EXPECT_EQ(held, (std::vector<int>{2, 7}));
  for (const bool interleaved : {false, true})
    for (const int frames : {5, 12, 75, 150}) {
      const HoldoutSplit split = SplitFrames(frames, 0.25, interleaved);
      int count = 0;
      for (int f = 0; f < frames; ++f) count += split.HeldOut(f);
      EXPECT_EQ(count, HeldOutFrames(frames, 0.25, interleaved)) << frames << (interleaved ? " interleaved" : " last");
    }
  EXPECT_TRUE(HoldoutInterleaved("interleaved", false));
  EXPECT_TRUE(HoldoutInterleaved("auto", true));
  EXPECT_FALSE(HoldoutInterleaved("auto", false));
  EXPECT_FALSE(HoldoutInterleaved("last", true));
}

}  // namespace
}  // namespace headforge
