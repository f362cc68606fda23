// A simulated scene ready for the benches: simulated and ingested once, and
// reused while the scene file and ingest's version stay the same.
#pragma once

#include <string>

#include <nlohmann/json.hpp>

#include "capture/capture_io.h"
#include "core/face_model.h"
#include "core/fs.h"
#include "core/status.h"

namespace headforge {

// Simulates `scene_file` into dir/capture and ingests it into dir/workspace
// (with `crop`; with the simulator's masks when `simulated_masks`) unless
// both are already there for the same scene file. `identity_seed` > 0
// simulates the scene with another random subject. Reads back the ingested
// capture and the simulator's ground_truth.json.
Status PrepareScene(const fs::path& scene_file, const fs::path& dir, const FaceModel& model, const std::string& data,
                    int threads, const std::string& crop, int identity_seed, bool simulated_masks,
                    IngestedCapture* capture, nlohmann::json* truth);

}  // namespace headforge
