// The jobs of the stage table (stage_table.cc): each binds its stage's options
// and runs the stage's library function on a workspace. One file each.
#pragma once

#include <memory>

#include "core/stage.h"

namespace headforge {

std::unique_ptr<StageJob> MakeIngestJob();
std::unique_ptr<StageJob> MakeCalibrateJob();
std::unique_ptr<StageJob> MakeAlignJob();
std::unique_ptr<StageJob> MakeTrackJob();
std::unique_ptr<StageJob> MakeTrainJob();
std::unique_ptr<StageJob> MakeExportJob();

}  // namespace headforge
