// The expressions the gan-avatar model's expression mapping learns from and
// is checked against: images (the generator's renders from a frontal
// training camera, or frames drawn like them) read by HeadForge's landmark
// model and tracker (the paper runs Deep3DFace there). Needs the full build
// (dlib, Ceres); the training pack's LibTorch-only trainer has no mapping.
#pragma once

#include <ATen/core/Tensor.h>

#include <string>
#include <vector>

#include "avatar/gan_avatar/expression_mapping.h"
#include "avatar/splat/splat_camera.h"
#include "core/face_model.h"
#include "core/progress.h"
#include "core/status.h"
#include "reconstruction/tracking_io.h"

namespace headforge {

struct RenderExpressionOptions {
  int landmark_size = 256;     // images are enlarged to this longer side for the landmark model
  std::string landmark_model;  // dlib's 68-point model file
  int threads = 1;
};

// Reads the expression of each of `images` ([M, 3, H, W] in [0, 1]: the
// GAN's renders, or frames drawn like them) seen from `cameras` (one for
// every image, or one each; any size: they are scaled to the images'):
// finds the 68 landmarks in a box placed where the subject's tracked face
// projects, and tracks every image as one frame of one sequence with the
// head fixed (the camera carries its pose), the identity shared and no
// smoothing. Fills `out`'s expressions, index (the images fitted), images,
// flagged and median residual; w is the caller's.
Status EstimateImageExpressions(const at::Tensor& images, const std::vector<SplatCamera>& cameras,
                                const FaceModel& model, const TrackingFile& tracking,
                                const RenderExpressionOptions& options, Progress* progress, RenderExpressions* out);

}  // namespace headforge
