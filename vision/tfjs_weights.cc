#include "vision/tfjs_weights.h"

#include <torch/torch.h>

#include <cmath>
#include <cstring>
#include <limits>

#include <nlohmann/json.hpp>

#include "core/json_io.h"

namespace headforge {

namespace {

// IEEE half precision to single.
float HalfToFloat(uint16_t h) {
  const uint32_t sign = uint32_t(h & 0x8000) << 16, exponent = (h >> 10) & 0x1f, mantissa = h & 0x3ff;
  float value;
  if (exponent == 0) {
    value = std::ldexp(float(mantissa), -24);
  } else if (exponent == 31) {
    value = mantissa ? std::numeric_limits<float>::quiet_NaN() : std::numeric_limits<float>::infinity();
  } else {
    value = std::ldexp(float(mantissa | 0x400), int(exponent) - 25);
  }
  return sign ? -value : value;
}

// How one tensor is stored in the shards.
struct Stored {
  std::string dtype;          // float32, int32 or bool: what it becomes
  std::string as = "";        // the bytes' type: float32, int32, bool, float16, uint8, uint16
  double scale = 1, min = 0;  // uint8 / uint16: value = min + scale * q
  size_t Width() const { return as == "uint8" || as == "bool" ? 1 : as == "uint16" || as == "float16" ? 2 : 4; }
};

// Decodes `count` values from `in` into a new tensor.
torch::Tensor Decode(const Stored& s, const unsigned char* in, int64_t count) {
  const bool integer = s.dtype == "int32";
  if (s.dtype == "bool") {
    torch::Tensor t = torch::empty({count}, torch::kBool);
    bool* out = t.data_ptr<bool>();
    for (int64_t i = 0; i < count; ++i) out[i] = in[i] != 0;
    return t;
  }
  std::vector<double> values(count);
  for (int64_t i = 0; i < count; ++i) {
    if (s.as == "uint8") {
      values[i] = s.min + s.scale * in[i];
    } else if (s.as == "uint16" || s.as == "float16") {
      const uint16_t q = uint16_t(in[2 * i] | (in[2 * i + 1] << 8));  // little-endian
      values[i] = s.as == "uint16" ? s.min + s.scale * q : HalfToFloat(q);
    } else if (s.as == "int32") {
      int32_t v;
      std::memcpy(&v, in + 4 * i, 4);
      values[i] = v;
    } else {
      float v;
      std::memcpy(&v, in + 4 * i, 4);
      values[i] = v;
    }
  }
  if (integer) {
    torch::Tensor t = torch::empty({count}, torch::kInt32);
    int32_t* out = t.data_ptr<int32_t>();
    for (int64_t i = 0; i < count; ++i) out[i] = static_cast<int32_t>(std::lround(values[i]));
    return t;
  }
  torch::Tensor t = torch::empty({count}, torch::kFloat32);
  float* out = t.data_ptr<float>();
  for (int64_t i = 0; i < count; ++i) out[i] = static_cast<float>(values[i]);
  return t;
}

}  // namespace

Status ReadTfjsWeightGroups(const nlohmann::json& groups, const fs::path& dir, const std::string& source,
                            std::map<std::string, torch::Tensor>* tensors) {
  const auto bad = [&](const std::string& why) {
    return Status::DataError(source + " is not a TensorFlow.js weights manifest: " + why);
  };
  tensors->clear();
  try {
    for (const nlohmann::json& group : groups) {
      std::string bytes;
      for (const nlohmann::json& path : group.at("paths")) {
        std::string shard;
        const Status read = ReadFileToString(dir / path.get<std::string>(), &shard);
        if (!read.ok())
          return Status::DataError(source + ": its weight shard " + (dir / path.get<std::string>()).string() +
                                   " cannot be read (" + read.message() + ")");
        bytes += shard;
      }
      size_t offset = 0;
      for (const nlohmann::json& spec : group.at("weights")) {
        const std::string name = spec.at("name").get<std::string>();
        Stored s;
        s.dtype = spec.at("dtype").get<std::string>();
        if (s.dtype != "float32" && s.dtype != "int32" && s.dtype != "bool")
          return bad(name + " has dtype " + s.dtype);
        s.as = s.dtype;
        if (spec.contains("quantization")) {
          const nlohmann::json& q = spec["quantization"];
          s.as = q.at("dtype").get<std::string>();
          if (s.as != "float16" && s.as != "uint8" && s.as != "uint16") return bad(name + " is stored as " + s.as);
          if (s.as != "float16") {
            s.scale = q.at("scale").get<double>();
            s.min = q.at("min").get<double>();
          }
        }
        const std::vector<int64_t> shape = spec.at("shape").get<std::vector<int64_t>>();
        int64_t count = 1;
        for (int64_t d : shape) {
          if (d < 0) return bad(name + " has a negative dimension");
          count *= d;
        }
        if (offset + s.Width() * size_t(count) > bytes.size()) return bad("its shards end before " + name);
        const auto* in = reinterpret_cast<const unsigned char*>(bytes.data()) + offset;
        (*tensors)[name] = Decode(s, in, count).view(shape);
        offset += s.Width() * size_t(count);
      }
    }
  } catch (const nlohmann::json::exception& e) {
    return bad(e.what());
  }
  return Status::Ok();
}

Status ReadTfjsWeights(const fs::path& manifest, std::map<std::string, torch::Tensor>* tensors) {
  nlohmann::json groups;
  HF_RETURN_IF_ERROR(ReadJson(manifest, &groups));
  return ReadTfjsWeightGroups(groups, manifest.parent_path(), manifest.string(), tensors);
}

}  // namespace headforge
