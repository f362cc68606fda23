#include "core/safetensors.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cstring>
#include <set>

namespace headforge {

int64_t SafeTensor::elements() const {
  int64_t n = 1;
  for (int64_t d : shape) n *= d;
  return n;
}

SafeTensor SafeTensor::Float32(const std::string& name, std::vector<int64_t> shape, const float* values) {
  SafeTensor t;
  t.name = name;
  t.shape = std::move(shape);
  t.bytes.resize(size_t(t.elements()) * sizeof(float));
  if (!t.bytes.empty()) std::memcpy(t.bytes.data(), values, t.bytes.size());
  return t;
}

std::vector<float> SafeTensor::ToFloats() const {
  std::vector<float> out(static_cast<size_t>(elements()));
  if (dtype == "F32") {
    std::memcpy(out.data(), bytes.data(), out.size() * sizeof(float));
  } else if (dtype == "F64") {
    for (size_t i = 0; i < out.size(); ++i) {
      double v;
      std::memcpy(&v, bytes.data() + i * sizeof(double), sizeof(double));
      out[i] = float(v);
    }
  } else {
    out.clear();
  }
  return out;
}

const SafeTensor* SafeTensorsFile::Find(const std::string& name) const {
  for (const SafeTensor& t : tensors)
    if (t.name == name) return &t;
  return nullptr;
}

int SafetensorsDtypeSize(const std::string& dtype) {
  static const std::map<std::string, int> sizes = {{"F64", 8}, {"F32", 4}, {"F16", 2}, {"BF16", 2}, {"I64", 8},
                                                   {"I32", 4}, {"I16", 2}, {"I8", 1},  {"U8", 1},   {"BOOL", 1}};
  const auto it = sizes.find(dtype);
  return it == sizes.end() ? 0 : it->second;
}

Status WriteSafetensors(const fs::path& path, const SafeTensorsFile& file) {
  nlohmann::ordered_json header = nlohmann::ordered_json::object();
  if (!file.metadata.empty()) header["__metadata__"] = file.metadata;
  std::set<std::string> names;
  uint64_t offset = 0;
  for (const SafeTensor& t : file.tensors) {
    if (t.name.empty() || t.name == "__metadata__" || !names.insert(t.name).second)
      return Status::InvalidArgument("safetensors: tensor name '" + t.name + "' is empty, reserved or repeated");
    const int size = SafetensorsDtypeSize(t.dtype);
    if (size == 0) return Status::InvalidArgument("safetensors: unknown dtype " + t.dtype + " for " + t.name);
    if (int64_t(t.bytes.size()) != t.elements() * size)
      return Status::InvalidArgument("safetensors: " + t.name + " holds " + std::to_string(t.bytes.size()) +
                                     " bytes, its shape and dtype say " + std::to_string(t.elements() * size));
    header[t.name] = {{"dtype", t.dtype}, {"shape", t.shape}, {"data_offsets", {offset, offset + t.bytes.size()}}};
    offset += t.bytes.size();
  }
  std::string json = header.dump();
  // Padded with spaces so the tensors start 8-byte aligned.
  json.append((8 - json.size() % 8) % 8, ' ');
  std::string contents(8, '\0');
  const uint64_t length = json.size();
  for (int i = 0; i < 8; ++i) contents[size_t(i)] = char((length >> (8 * i)) & 0xff);
  contents += json;
  contents.reserve(contents.size() + offset);
  for (const SafeTensor& t : file.tensors) contents.append(reinterpret_cast<const char*>(t.bytes.data()), t.bytes.size());
  return WriteFileAtomic(path, contents);
}

Status ReadSafetensors(const fs::path& path, SafeTensorsFile* file) {
  std::string contents;
  HF_RETURN_IF_ERROR(ReadFileToString(path, &contents));
  const std::string where = "safetensors file " + path.string();
  if (contents.size() < 8) return Status::DataError(where + " is shorter than its 8-byte header length");
  uint64_t length = 0;
  for (int i = 0; i < 8; ++i) length |= uint64_t(uint8_t(contents[size_t(i)])) << (8 * i);
  if (length > contents.size() - 8) return Status::DataError(where + " is truncated: its header says " +
                                                             std::to_string(length) + " bytes of JSON");
  nlohmann::json header;
  try {
    header = nlohmann::json::parse(contents.substr(8, length));
  } catch (const nlohmann::json::exception& e) {
    return Status::DataError(where + ": the header is not JSON (" + e.what() + ")");
  }
  if (!header.is_object()) return Status::DataError(where + ": the header is not a JSON object");
  const uint64_t data_start = 8 + length, data_size = contents.size() - data_start;
  SafeTensorsFile out;
  struct Range { uint64_t begin, end; std::string name; };
  std::vector<Range> ranges;
  try {
    for (const auto& [name, entry] : header.items()) {
      if (name == "__metadata__") {
        for (const auto& [key, value] : entry.items()) out.metadata[key] = value.get<std::string>();
        continue;
      }
      SafeTensor t;
      t.name = name;
      t.dtype = entry.at("dtype").get<std::string>();
      t.shape = entry.at("shape").get<std::vector<int64_t>>();
      const auto offsets = entry.at("data_offsets").get<std::vector<uint64_t>>();
      const int size = SafetensorsDtypeSize(t.dtype);
      if (size == 0) return Status::DataError(where + ": unknown dtype " + t.dtype + " for " + name);
      if (offsets.size() != 2 || offsets[0] > offsets[1] || offsets[1] > data_size)
        return Status::DataError(where + ": " + name + "'s byte range lies outside the file");
      for (int64_t d : t.shape)
        if (d < 0) return Status::DataError(where + ": " + name + " has a negative dimension");
      if (offsets[1] - offsets[0] != uint64_t(t.elements() * size))
        return Status::DataError(where + ": " + name + "'s byte range does not match its shape and dtype");
      t.bytes.assign(contents.begin() + std::ptrdiff_t(data_start + offsets[0]),
                     contents.begin() + std::ptrdiff_t(data_start + offsets[1]));
      ranges.push_back({offsets[0], offsets[1], name});
      out.tensors.push_back(std::move(t));
    }
  } catch (const nlohmann::json::exception& e) {
    return Status::DataError(where + ": a header entry is malformed (" + e.what() + ")");
  }
  std::sort(ranges.begin(), ranges.end(), [](const Range& a, const Range& b) { return a.begin < b.begin; });
  uint64_t next = 0;
  for (const Range& r : ranges) {
    if (r.begin != next) return Status::DataError(where + ": " + r.name + "'s bytes overlap another tensor or leave a gap");
    next = r.end;
  }
  // Tensors in file order, the order the writer gave them.
  std::vector<SafeTensor> ordered;
  for (const Range& r : ranges)
    for (SafeTensor& t : out.tensors)
      if (t.name == r.name) ordered.push_back(std::move(t));
  out.tensors = std::move(ordered);
  *file = std::move(out);
  return Status::Ok();
}

}  // namespace headforge
