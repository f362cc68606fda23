#include "capture/matte.h"

#include <opencv2/imgproc.hpp>

#include "core/log.h"
#include "core/paths.h"
#include "vision/person_matte.h"

namespace headforge {

Status MatteOptions::Check() const {
  if (method == "auto" || method == "grabcut") return Status::Ok();
  for (const std::string& kind : PersonMatte::Kinds())
    if (method == kind) return Status::Ok();
  return Status::InvalidArgument("--matte must be auto, selfie, meet, rvm or grabcut, not '" + method + "'");
}

FrameMasker::FrameMasker() = default;
FrameMasker::~FrameMasker() = default;

Status FrameMasker::Create(const MatteOptions& options, std::unique_ptr<FrameMasker>* masker) {
  HF_RETURN_IF_ERROR(options.Check());
  std::unique_ptr<FrameMasker> m(new FrameMasker);
  m->grabcut_ = options.grabcut;
  m->method_ = options.method == "auto" ? MatteOptions::kDefaultNetwork : options.method;
  if (m->method_ != "grabcut") {
    const std::string dir = options.models_dir.empty() ? DefaultVisionModelsDir() : options.models_dir;
    const Status load = PersonMatte::Load(dir, m->method_, &m->matte_);
    if (!load.ok()) {
      // auto falls back where the models are not installed, not where one is damaged.
      if (options.method != "auto" || load.code() != Status::Code::kNotFound)
        return load.WithContext("--matte " + options.method);
      HF_LOG(Warning) << "ingest: " << load.message() << "; masking with GrabCut instead (--matte grabcut)";
      m->method_ = "grabcut";
    }
  }
  if (m->matte_ && PersonMatte::Licence(m->method_) != "Apache-2.0")
    HF_LOG(Info) << "ingest: masks by " << m->method_ << ", whose weights are " << PersonMatte::Licence(m->method_)
                 << (options.method == "auto" ? " (--matte selfie, meet or grabcut for others)" : "");
  *masker = std::move(m);
  return Status::Ok();
}

bool FrameMasker::sequential() const { return matte_ && matte_->recurrent(); }

void FrameMasker::StartSequence() {
  if (matte_) matte_->Reset();
}

cv::Mat FrameMasker::Mask(const cv::Mat& frame, const Landmarks68& landmarks, uint64_t seed, cv::Mat* alpha) {
  if (!matte_) {
    if (alpha) alpha->release();
    return HeadMask(frame, landmarks, grabcut_, seed);
  }
  const cv::Mat soft = matte_->Alpha(frame);  // CV_32F in [0, 1]
  cv::Mat mask = soft >= 0.5f;  // 255 where the person covers at least half the pixel
  if (alpha) soft.convertTo(*alpha, CV_8U, 255.0);
  return mask;
}

}  // namespace headforge
