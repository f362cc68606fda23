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

}  // namespace headforge
