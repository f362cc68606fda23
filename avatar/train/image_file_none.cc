// The LibTorch-only build's image files: none (image_file.h).
#include "avatar/train/image_file.h"

namespace headforge {

Status WriteTensorImage(const fs::path&, const torch::Tensor&) { return Status::Ok(); }
bool ImageFilesWritten() { return false; }

}  // namespace headforge
