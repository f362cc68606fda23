#include "core/paths.h"

#include <cstdlib>

namespace headforge {

std::string DefaultDataDir() {
  if (const char* env = std::getenv("HEADFORGE_DATA"); env && *env) return env;
  return HEADFORGE_SHARED_DATA;
}

std::string DefaultVisionModelsDir() {
  if (const char* env = std::getenv("HEADFORGE_VISION_MODELS"); env && *env) return env;
  return HEADFORGE_VISION_MODELS;
}

std::string DefaultLandmarkModel() { return HEADFORGE_DLIB_LANDMARKS; }
std::string DefaultColmapExecutable() { return HEADFORGE_COLMAP_EXECUTABLE; }
std::string HeadForgeVersion() { return HEADFORGE_VERSION; }

}  // namespace headforge
