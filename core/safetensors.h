// .safetensors files: an 8-byte little-endian header length, a JSON header
// naming each tensor's dtype, shape and byte range, then the tensors' raw
// little-endian bytes. The format other tools (PyTorch, JAX, candle) load
// network weights from; written and read here without LibTorch.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "core/fs.h"
#include "core/status.h"

namespace headforge {

struct SafeTensor {
  std::string name;
  std::string dtype = "F32";    // F64 F32 F16 BF16 I64 I32 I16 I8 U8 BOOL
  std::vector<int64_t> shape;   // empty: a scalar
  std::vector<uint8_t> bytes;   // row-major, little-endian

  int64_t elements() const;
  // A float32 tensor of `shape` from `values` (row-major).
  static SafeTensor Float32(const std::string& name, std::vector<int64_t> shape, const float* values);
  // The values of an F32 or F64 tensor as floats.
  std::vector<float> ToFloats() const;
};

struct SafeTensorsFile {
  std::map<std::string, std::string> metadata;  // "__metadata__": strings only
  std::vector<SafeTensor> tensors;               // written in this order

  const SafeTensor* Find(const std::string& name) const;
};

// Bytes per element of a dtype name, 0 for an unknown one.
int SafetensorsDtypeSize(const std::string& dtype);

// Written to a temporary name and renamed; names must be unique and non-empty.
Status WriteSafetensors(const fs::path& path, const SafeTensorsFile& file);
// Checks the header against the file: sizes, dtypes, byte ranges in order
// without gaps or overlaps.
Status ReadSafetensors(const fs::path& path, SafeTensorsFile* file);

}  // namespace headforge
