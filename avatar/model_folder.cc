#include "avatar/model_folder.h"

namespace headforge {

fs::path LatestModelFolder(const fs::path& workspace) {
  fs::path latest;
  fs::file_time_type newest{};
  for (const char* folder : {"gaussian_style", "gan_avatar"}) {
    const fs::path dir = workspace / "models" / folder;
    std::error_code ec;
    const auto written = fs::last_write_time(dir / "config.json", ec);
    if (ec) continue;
    if (latest.empty() || written > newest) {
      latest = dir;
      newest = written;
    }
  }
  return latest;
}

}  // namespace headforge
