#include "calibration/colmap_tool.h"

#include <array>
#include <cstdio>
#include <memory>

namespace headforge {

Status ColmapVersion(const std::string& executable, std::string* version) {
  const std::string command = "QT_QPA_PLATFORM=offscreen '" + executable + "' -h 2>&1";
  std::unique_ptr<FILE, int (*)(FILE*)> pipe(::popen(command.c_str(), "r"), ::pclose);
  if (!pipe) return Status::NotFound("cannot run " + executable);
  std::array<char, 512> line{};
  while (std::fgets(line.data(), line.size(), pipe.get())) {
    std::string text(line.data());
    const auto pos = text.find("COLMAP ");
    if (pos != std::string::npos) {
      const auto end = text.find(" --", pos);
      *version = text.substr(pos, end == std::string::npos ? std::string::npos : end - pos);
      while (!version->empty() && (version->back() == '\n' || version->back() == ' '))
        version->pop_back();
      return Status::Ok();
    }
  }
  return Status::NotFound(executable + " did not print a COLMAP version; install Debian's colmap "
                          "package (scripts/install_deps.sh)");
}

}  // namespace headforge
