#include "export/gaussian_ply.h"

#include <cmath>
#include <cstring>
#include <map>
#include <sstream>

namespace headforge {

Status GaussianCloud::Check() const {
  const size_t n = size();
  if (sh_degree < 0 || sh_degree > 3) return Status::InvalidArgument("SH degree must be in [0, 3]");
  if (means.size() != 3 * n || sh_dc.size() != 3 * n || log_scales.size() != 3 * n || rotations.size() != 4 * n ||
      sh_rest.size() != 3 * n * static_cast<size_t>(RestPerChannel()))
    return Status::InvalidArgument("Gaussian cloud arrays disagree with its size " + std::to_string(n));
  return Status::Ok();
}

namespace {
constexpr int kRestPerChannel3 = 15;  // degree 3
}  // namespace

Status WriteGaussianPly(const fs::path& path, const GaussianCloud& cloud) {
  HF_RETURN_IF_ERROR(cloud.Check());
  const size_t n = cloud.size();
  std::ostringstream header;
  header << "ply\nformat binary_little_endian 1.0\nelement vertex " << n << "\n";
  for (const char* name : {"x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"})
    header << "property float " << name << "\n";
  for (int i = 0; i < 3 * kRestPerChannel3; ++i) header << "property float f_rest_" << i << "\n";
  header << "property float opacity\n";
  for (int i = 0; i < 3; ++i) header << "property float scale_" << i << "\n";
  for (int i = 0; i < 4; ++i) header << "property float rot_" << i << "\n";
  header << "end_header\n";
  constexpr int kFloats = 9 + 3 * kRestPerChannel3 + 1 + 3 + 4;  // 62
  std::string data = header.str();
  const size_t offset = data.size();
  data.resize(offset + n * kFloats * sizeof(float));
  const int k = cloud.RestPerChannel();
  std::vector<float> row(kFloats);
  for (size_t i = 0; i < n; ++i) {
    std::fill(row.begin(), row.end(), 0.0f);
    for (int c = 0; c < 3; ++c) {
      row[c] = cloud.means[3 * i + c];
      row[6 + c] = cloud.sh_dc[3 * i + c];
      for (int j = 0; j < k; ++j) row[9 + c * kRestPerChannel3 + j] = cloud.sh_rest[(i * 3 + c) * k + j];
      row[55 + c] = cloud.log_scales[3 * i + c];
    }
    row[54] = cloud.opacities[i];
    for (int c = 0; c < 4; ++c) row[58 + c] = cloud.rotations[4 * i + c];
    std::memcpy(&data[offset + i * kFloats * sizeof(float)], row.data(), kFloats * sizeof(float));
  }
  return WriteFileAtomic(path, data);
}

Status ReadGaussianPly(const fs::path& path, GaussianCloud* cloud) {
  std::string bytes;
  HF_RETURN_IF_ERROR(ReadFileToString(path, &bytes));
  const std::string end = "end_header\n";
  const size_t header_end = bytes.find(end);
  if (bytes.rfind("ply\n", 0) != 0 || header_end == std::string::npos)
    return Status::DataError(path.string() + " is not a PLY file");
  std::istringstream header(bytes.substr(0, header_end));
  std::string line, format;
  size_t count = 0;
  bool in_vertex = false;
  struct Property {
    size_t offset;
    bool is_double;
  };
  std::map<std::string, Property> props;
  size_t stride = 0;
  while (std::getline(header, line)) {
    std::istringstream in(line);
    std::string word;
    in >> word;
    if (word == "format") {
      in >> format;
    } else if (word == "element") {
      std::string name;
      in >> name >> count;
      in_vertex = name == "vertex";
      if (!in_vertex && count > 0) return Status::DataError(path.string() + ": only a vertex element is supported");
    } else if (word == "property" && in_vertex) {
      std::string type, name;
      in >> type >> name;
      if (type == "list") return Status::DataError(path.string() + ": list properties are not supported");
      const bool is_double = type == "double" || type == "float64";
      if (!is_double && type != "float" && type != "float32")
        return Status::DataError(path.string() + ": property " + name + " has type " + type + "; expected float");
      props[name] = {stride, is_double};
      stride += is_double ? 8 : 4;
    }
  }
  if (format != "binary_little_endian")
    return Status::DataError(path.string() + ": format " + format + " is not supported (binary_little_endian only)");
  const size_t body = header_end + end.size();
  if (bytes.size() < body + count * stride)
    return Status::DataError(path.string() + " is truncated: " + std::to_string(count) + " Gaussians announced, " +
                             std::to_string((bytes.size() - body) / std::max<size_t>(1, stride)) + " present");
  for (const char* required : {"x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2",
                               "rot_0", "rot_1", "rot_2", "rot_3"})
    if (!props.count(required)) return Status::DataError(path.string() + " lacks the property " + required);
  int rest = 0;
  while (props.count("f_rest_" + std::to_string(rest))) ++rest;
  if (rest % 3 != 0) return Status::DataError(path.string() + ": f_rest count " + std::to_string(rest) + " is not 3 x K");
  const int k = rest / 3;
  int degree = 0;
  while ((degree + 1) * (degree + 1) - 1 < k) ++degree;
  if ((degree + 1) * (degree + 1) - 1 != k || degree > 3)
    return Status::DataError(path.string() + ": " + std::to_string(k) + " SH coefficients per channel fit no degree");
  auto get = [&](size_t i, const std::string& name) {
    const Property& p = props.at(name);
    const char* at = bytes.data() + body + i * stride + p.offset;
    if (p.is_double) {
      double v;
      std::memcpy(&v, at, 8);
      return static_cast<float>(v);
    }
    float v;
    std::memcpy(&v, at, 4);
    return v;
  };
  GaussianCloud out;
  out.sh_degree = degree;
  out.means.resize(3 * count);
  out.sh_dc.resize(3 * count);
  out.sh_rest.resize(3 * count * k);
  out.opacities.resize(count);
  out.log_scales.resize(3 * count);
  out.rotations.resize(4 * count);
  for (size_t i = 0; i < count; ++i) {
    for (int c = 0; c < 3; ++c) {
      out.means[3 * i + c] = get(i, std::string(1, "xyz"[c]));
      out.sh_dc[3 * i + c] = get(i, "f_dc_" + std::to_string(c));
      out.log_scales[3 * i + c] = get(i, "scale_" + std::to_string(c));
      for (int j = 0; j < k; ++j) out.sh_rest[(i * 3 + c) * k + j] = get(i, "f_rest_" + std::to_string(c * k + j));
    }
    out.opacities[i] = get(i, "opacity");
    for (int c = 0; c < 4; ++c) out.rotations[4 * i + c] = get(i, "rot_" + std::to_string(c));
  }
  *cloud = std::move(out);
  return Status::Ok();
}

}  // namespace headforge
