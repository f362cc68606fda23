// Training from a pack (avatar_train.h's TrainFromPack): needs LibTorch alone.
#include <torch/torch.h>

#include <nlohmann/json.hpp>

#include "avatar/avatar_train.h"
#include "avatar/gan_avatar/trainer.h"
#include "avatar/gaussian_style/trainer.h"
#include "avatar/model_table.h"
#include "avatar/torch_runtime.h"
#include "avatar/train/dataset_pack.h"
#include "avatar/train/distributed.h"
#include "avatar/train/image_file.h"
#include "core/log.h"

namespace headforge {

namespace {

// The field `key` of `options` or of one of its blocks (objects within it),
// or null: the field names are unique across the blocks.
nlohmann::json* FindField(nlohmann::json* options, const std::string& key) {
  const auto it = options->find(key);
  if (it != options->end() && !it->is_object()) return &*it;
  for (nlohmann::json& value : *options)  // an object's values
    if (value.is_object())
      if (nlohmann::json* found = FindField(&value, key)) return found;
  return nullptr;
}

// `settings` ("field=value") over `options`' JSON form; a value that does not
// parse as JSON is a string.
Status ApplySettings(const std::vector<std::string>& settings, nlohmann::json* options) {
  for (const std::string& setting : settings) {
    const size_t eq = setting.find('=');
    const std::string key = setting.substr(0, eq);
    nlohmann::json* field = eq == std::string::npos ? nullptr : FindField(options, key);
    if (!field)
      return Status::InvalidArgument("--set " + setting + ": no option '" + key +
                                     "' (the names are headforge train's options with _ for -: max_minutes, "
                                     "decoder_steps, ...)");
    nlohmann::json value = nlohmann::json::parse(setting.substr(eq + 1), nullptr, /*allow_exceptions=*/false);
    if (value.is_discarded()) value = setting.substr(eq + 1);
    const nlohmann::json& old = *field;
    const bool fits = (old.is_number() && value.is_number()) || old.type() == value.type();
    if (!fits)
      return Status::InvalidArgument("--set " + setting + ": " + key + " takes a " + std::string(old.type_name()) +
                                     " such as " + old.dump());
    *field = value;
  }
  return Status::Ok();
}

}  // namespace

Status TrainFromPack(const fs::path& pack, const std::vector<std::string>& settings, const fs::path& out_dir,
                     Progress* progress, TrainSummary* summary, Collective* collective) {
  UseTensorThreads();
  AvatarDataset data;
  nlohmann::json recorded;
  HF_RETURN_IF_ERROR(ReadDatasetPack(pack, &data, &recorded));
  TrainOptions options;
  try {
    nlohmann::json resolved = ToJson(TrainOptionsFromJson(recorded));
    // Fields a record leaves out at their defaults can be set too.
    if (const auto style = resolved.find(std::string(kGaussianStyle.folder));
        style != resolved.end() && style->is_object() && !style->contains("views_per_step"))
      (*style)["views_per_step"] = 0;
    HF_RETURN_IF_ERROR(ApplySettings(settings, &resolved));
    options = TrainOptionsFromJson(resolved);
  } catch (const nlohmann::json::exception& e) {
    return Status::DataError(pack.string() + ": its training options do not read (" + e.what() +
                             "); write the pack again with this version's headforge pack");
  }
  // A generator file named in the pack must be on this machine too.
  const DecoderTrainOptions& decoder = options.gaussian_style.decoder;
  if (!decoder.decoder_init.empty()) {
    std::error_code ec;
    if (!fs::is_regular_file(decoder.decoder_init, ec))
      return Status::InvalidArgument("pack: its --decoder-init " + decoder.decoder_init +
                                     " is not on this machine; put it at the same path");
  }
  HF_RETURN_IF_ERROR(options.Check().WithContext(pack.string()));
  if (decoder.decoder_steps > 0 && decoder.adversarial_weight > 0 && !data.train.empty() &&
      !data.train.front().uv_map.defined())
    return Status::InvalidArgument(pack.string() + " has no UV maps for stage 3's discriminator: write it with "
                                   "--decoder-steps (and an --adversarial-weight above 0), or set "
                                   "adversarial_weight=0");
  HF_LOG(Info) << "train: " << data.train.size() << " training and " << data.test.size() << " held-out views at "
               << data.width << "x" << data.height << " from " << pack.string() << " on " << options.device;
  if (!ImageFilesWritten())
    HF_LOG(Info) << "train: this build writes no images (previews, held_out/): headforge render --held-out "
                    "--side-by-side draws them once the model is in its workspace";
  options.collective = collective;
  if (kGaussianStyle.Is(options.model)) return TrainGaussianStyleRun(options, data, out_dir, progress, summary);
  if (collective != nullptr) HF_RETURN_IF_ERROR(CheckDataParallelModel(options.model, "headforge-train"));
  if (!options.gan_avatar.generator_from.empty())
    return Status::InvalidArgument("--set generator_from: a pack trains the GAN itself; --generator-from is headforge "
                                   "train's, on the workspace");
  HF_RETURN_IF_ERROR(TrainGanAvatar(options, data, /*track_images=*/{}, out_dir, progress, summary));
  if (options.gan_avatar.mapping_steps > 0)
    HF_LOG(Info) << "train: the GAN is trained; on the workspace's machine, headforge train --workspace WS --model "
                    "gan-avatar --generator-from " << out_dir.string()
                 << " (this folder copied there) adds the expression mapping";
  return Status::Ok();
}

}  // namespace headforge
