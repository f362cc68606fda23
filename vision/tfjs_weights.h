// The TensorFlow.js weights format: a manifest (a JSON list of groups, each
// naming its shard files and its tensors: name, shape, dtype, and optionally
// a quantization) and the shards, the tensors' bytes end to end in the
// manifest's order. Graph models hold the manifest in model.json's
// "weightsManifest"; layers models (face-api's) in a file of their own.
#pragma once

#include <torch/types.h>

#include <map>
#include <string>

#include <nlohmann/json_fwd.hpp>

#include "core/fs.h"
#include "core/status.h"

namespace headforge {

// The tensors of `groups` by name, their shards read from `dir`: float32
// (also where stored quantized: uint8 or uint16 as value = min + scale * q,
// or float16), int32 (rounded where quantized) and bool. `source` names the
// file in errors. DataError when a shard is missing or short, or a dtype unknown.
Status ReadTfjsWeightGroups(const nlohmann::json& groups, const fs::path& dir, const std::string& source,
                            std::map<std::string, torch::Tensor>* tensors);

// The same from a manifest file, its shards beside it.
Status ReadTfjsWeights(const fs::path& manifest, std::map<std::string, torch::Tensor>* tensors);

}  // namespace headforge
