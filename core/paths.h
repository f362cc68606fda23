// Default locations of data the tool reads but does not ship.
#pragma once

#include <string>

namespace headforge {

// The shared data folder: $HEADFORGE_DATA if set, else the path configured at
// build time (../shared/data beside the source tree).
std::string DefaultDataDir();
// The dlib 68-point landmark model installed by Debian's libdlib-data.
std::string DefaultLandmarkModel();
// The folder of the front end's learned models (face mesh, person mattes):
// $HEADFORGE_VISION_MODELS if set, else .tools/human-models/models in the
// source tree, where scripts/install_deps.sh puts them.
std::string DefaultVisionModelsDir();
// The colmap executable found at build time.
std::string DefaultColmapExecutable();
// "0.1.0".
std::string HeadForgeVersion();

}  // namespace headforge
