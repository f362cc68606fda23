// JSON files of the workspace (capture.json, landmarks.json, ...), written atomically.
#pragma once

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include "core/fs.h"
#include "core/status.h"

namespace headforge {

Status ReadJson(const fs::path& path, nlohmann::json* json);
// Writes `json` indented by `indent` (-1: compact) through a temporary file.
Status WriteJsonAtomic(const fs::path& path, const nlohmann::json& json, int indent = 1);

// Reads a workspace artefact written by `stage` (capture.json by ingest,
// tracking.json by track, ...): the JSON, with its "version" field equal to
// `version`. A missing file is NotFound and a file of another version a
// DataError, each naming the stage to run (again).
Status ReadArtefact(const fs::path& path, int version, const std::string& stage, nlohmann::json* json);

// A rigid transform as a row-major 4x4 array of arrays, and back (throws
// nlohmann::json::exception on a malformed array).
nlohmann::json PoseToJson(const Eigen::Isometry3d& pose);
Eigen::Isometry3d PoseFromJson(const nlohmann::json& rows);

}  // namespace headforge
