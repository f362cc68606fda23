// The masks ingest writes for each output frame: a learned person matte
// (vision/person_matte.h: MediaPipe's selfie or Meet segmentation, or Robust
// Video Matting) thresholded at half coverage, or GrabCut seeded from the
// landmarks (capture/face_mask.h), today's path and the fallback when the
// models are not installed.
#pragma once

#include <memory>
#include <string>

#include <opencv2/core.hpp>

#include "capture/face_mask.h"
#include "capture/landmarks.h"
#include "core/status.h"

namespace headforge {

class PersonMatte;

struct MatteOptions {
  // "auto" (the default network, or GrabCut with a warning where the models
  // are not installed), "selfie", "meet", "rvm" (GPL-3.0 weights) or
  // "grabcut".
  std::string method = "auto";
  // Folder of the networks' files (default: DefaultVisionModelsDir()).
  std::string models_dir;
  HeadMaskOptions grabcut;

  Status Check() const;
  // The default network of "auto": MediaPipe's selfie segmentation. Its
  // masks agree with the simulator's to 0.991 before a backdrop and 0.984
  // before a defocused room (bench front-end; GrabCut 0.960 and 0.881),
  // within 0.01 of Robust Video Matting's (0.996 and 0.992), at 4 ms a frame
  // against 85 and with Apache-2.0 weights where RVM's are GPL-3.0.
  static constexpr const char* kDefaultNetwork = "selfie";
};

class FrameMasker {
 public:
  // Loads the network `options` names. "auto" without the model files warns
  // once and masks with GrabCut; a named network's missing or damaged file is
  // an error that names the install step.
  static Status Create(const MatteOptions& options, std::unique_ptr<FrameMasker>* masker);
  ~FrameMasker();

  // What masks: selfie, meet, rvm or grabcut.
  const std::string& method() const { return method_; }
  // A recurrent network: frames must come in their video's order, one at a
  // time (Mask is then not to be called from several threads), and
  // StartSequence() before each camera.
  bool sequential() const;
  void StartSequence();

  // The 8-bit mask (255 on the person, or the head for GrabCut) of an output
  // frame, and where a network gave it its soft alpha (CV_8U, 0-255) in
  // `alpha` (empty for GrabCut). `landmarks` (frame pixels) seed GrabCut;
  // `seed` its random start.
  cv::Mat Mask(const cv::Mat& frame, const Landmarks68& landmarks, uint64_t seed, cv::Mat* alpha = nullptr);

 private:
  FrameMasker();
  std::string method_;
  HeadMaskOptions grabcut_;
  std::unique_ptr<PersonMatte> matte_;
};

}  // namespace headforge
