// face-api's face-recognition network in LibTorch, with a reader of the
// TensorFlow.js weights format it ships in (npm's @vladmandic/face-api, MIT:
// model/face_recognition_model-weights_manifest.json and its shard).
//
// The network (dlib's ResNet descriptor as face-api ports it): a 150x150 RGB
// crop, minus the mean colour (122.782, 117.001, 104.298), over 255; a 7x7
// convolution of stride 2 without padding and a 3x3 max pool of stride 2;
// residual blocks of 32, 64, 128 and 256 channels, each convolution followed
// by its bias, a per-channel scale and offset, and a ReLU (the second of a
// block's two after the sum); a block that halves the size starts with a 3x3
// convolution of stride 2 without padding, and its shortcut is a 2x2 average
// pool with the new channels zero, the block's output padded by a zero row
// and column where the pool comes out one larger; the spatial mean; a 256 x
// 128 matrix. The descriptor is 128-d; the network was trained to put one
// person's faces within a Euclidean distance of 0.6.
#pragma once

#include <torch/nn/module.h>
#include <torch/types.h>

#include <map>
#include <string>

#include "core/fs.h"
#include "core/status.h"

namespace headforge {

class FaceRecognitionNetImpl : public torch::nn::Module {
 public:
  // The weights by face-api's names (conv32_down/conv/filters, ..., fc);
  // missing ones or wrong shapes are a DataError.
  static Status Create(const std::map<std::string, torch::Tensor>& weights,
                       std::shared_ptr<FaceRecognitionNetImpl>* net);
  // crops [B, 3, 150, 150], RGB in 0..255 -> descriptors [B, 128].
  torch::Tensor forward(const torch::Tensor& crops);

 private:
  struct Conv {
    torch::Tensor filters, bias, scale, offset;  // [out, in, k, k] and [out] each
  };
  torch::Tensor Apply(const Conv& conv, const torch::Tensor& x, int stride, bool relu) const;
  torch::Tensor Residual(const std::string& block, const torch::Tensor& x) const;
  torch::Tensor ResidualDown(const std::string& block, const torch::Tensor& x) const;
  std::map<std::string, Conv> convs_;
  torch::Tensor fc_;  // [256, 128]
};
TORCH_MODULE(FaceRecognitionNet);

}  // namespace headforge
