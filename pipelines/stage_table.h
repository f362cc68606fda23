// The pipeline's stages, in order, as one table: name, upstream stages,
// options, what each reads and writes, and its job. `headforge <stage>`,
// `headforge run`, `headforge status` and the fingerprints all come from it;
// adding a stage is one entry here plus its own files.
#pragma once

#include <string>
#include <vector>

#include "core/stage.h"

namespace headforge {

const std::vector<StageEntry>& StageTable();
// nullptr when no stage has this name.
const StageEntry* FindStage(const std::string& name);
std::vector<std::string> StageNames();

// `headforge <stage>`: the stage's options and the common ones, then the stage.
int StageCommand(const StageEntry& entry, const std::vector<std::string>& args);
// `headforge run`: every available stage in order.
int RunCommand(const std::vector<std::string>& args);

}  // namespace headforge
