// The data the gan-avatar model's expression mapping learns from: latents
// sampled, rendered from a frontal training camera, and each render's
// expression estimated by HeadForge's landmark model and tracker (the paper
// runs Deep3DFace there). Needs the full build (dlib, Ceres); the training
// pack's LibTorch-only trainer has no mapping.
#pragma once

#include <ATen/core/Generator.h>

#include <string>

#include "avatar/gan_avatar/expression_mapping.h"
#include "avatar/gan_avatar/model.h"
#include "core/face_model.h"
#include "core/progress.h"
#include "core/status.h"
#include "reconstruction/tracking_io.h"

namespace headforge {

struct RenderExpressionOptions {
  int samples = 256;           // latents rendered
  int landmark_size = 256;     // renders are enlarged to this longer side for the landmark model
  std::string landmark_model;  // dlib's 68-point model file
  double background = 0.5;
  int threads = 1;
};

// Samples latents z ~ N(0, I) from `generator` (z drawn from `random`),
// renders each from `camera` (the volume render's size) at out_width x
// out_height, finds the 68 landmarks in a box placed where the subject's
// tracked face projects, and tracks every render as one frame of one
// sequence with the camera fixed, the identity shared and no smoothing.
Status EstimateRenderExpressions(GanGenerator& generator, const SplatCamera& camera, int out_width, int out_height,
                                 const FaceModel& model, const TrackingFile& tracking,
                                 const RenderExpressionOptions& options, at::Generator& random, Progress* progress,
                                 RenderExpressions* out);

}  // namespace headforge
