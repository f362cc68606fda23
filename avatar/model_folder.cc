#include "avatar/model_folder.h"

#include "avatar/model_table.h"

namespace headforge {

fs::path LatestModelFolder(const fs::path& workspace) {
  fs::path latest;
  fs::file_time_type newest{};
  for (const AvatarModel& model : kAvatarModels) {
    const fs::path dir = model.Dir(workspace);
    std::error_code ec;
    const auto written = fs::last_write_time(dir / std::string(model.marker), ec);
    if (ec) continue;
    if (latest.empty() || written > newest) {
      latest = dir;
      newest = written;
    }
  }
  return latest;
}

}  // namespace headforge
