#include "core/json_io.h"

namespace headforge {

Status ReadJson(const fs::path& path, nlohmann::json* json) {
  std::string text;
  HF_RETURN_IF_ERROR(ReadFileToString(path, &text));
  try {
    *json = nlohmann::json::parse(text);
  } catch (const nlohmann::json::exception& e) {
    return Status::DataError(path.string() + " is not valid JSON: " + e.what());
  }
  return Status::Ok();
}

Status WriteJsonAtomic(const fs::path& path, const nlohmann::json& json, int indent) {
  return WriteFileAtomic(path, json.dump(indent) + "\n");
}

Status ReadArtefact(const fs::path& path, int version, const std::string& stage, nlohmann::json* json) {
  std::error_code ec;
  if (!fs::exists(path, ec)) {
    return Status::NotFound("no " + path.filename().string() + " in " + path.parent_path().string() +
                            " (run headforge " + stage + " first)");
  }
  if (Status read = ReadJson(path, json); !read.ok()) {
    if (read.code() != Status::Code::kDataError) return read;
    return Status::DataError(read.message() + "; run headforge " + stage + " again to rewrite it");
  }
  const auto it = json->find("version");
  if (it == json->end() || !it->is_number_integer() || it->get<int>() != version) {
    const std::string found = it == json->end() || !it->is_number_integer() ? "no version" : "version " + it->dump();
    const bool newer = it != json->end() && it->is_number_integer() && it->get<int>() > version;
    return Status::DataError(path.string() + " has " + found + ", and this HeadForge reads version " +
                             std::to_string(version) + (newer ? " (it was written by a newer HeadForge)" : "") +
                             "; run headforge " + stage + " again to rewrite it (headforge run redoes " + stage +
                             " and the stages after it)");
  }
  return Status::Ok();
}

nlohmann::json PoseToJson(const Eigen::Isometry3d& pose) {
  nlohmann::json rows = nlohmann::json::array();
  for (int r = 0; r < 4; ++r)
    rows.push_back({pose.matrix()(r, 0), pose.matrix()(r, 1), pose.matrix()(r, 2), pose.matrix()(r, 3)});
  return rows;
}

Eigen::Isometry3d PoseFromJson(const nlohmann::json& rows) {
  Eigen::Matrix4d m;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) m(r, c) = rows.at(r).at(c).get<double>();
  Eigen::Isometry3d pose;
  pose.matrix() = m;
  return pose;
}

}  // namespace headforge
