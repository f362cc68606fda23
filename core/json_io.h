// JSON files of the workspace (capture.json, landmarks.json, ...), written atomically.
#pragma once

#include <nlohmann/json.hpp>

#include "core/fs.h"
#include "core/status.h"

namespace headforge {

Status ReadJson(const fs::path& path, nlohmann::json* json);
// Writes `json` indented by `indent` (-1: compact) through a temporary file.
Status WriteJsonAtomic(const fs::path& path, const nlohmann::json& json, int indent = 1);

}  // namespace headforge
