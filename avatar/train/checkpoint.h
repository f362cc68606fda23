// A training run's state on disk: named tensors and numbers in one file,
// written through a temporary name and renamed, so a kill while saving leaves
// the previous checkpoint whole. Everything a loop needs to continue as if it
// had never stopped goes in (parameters, optimiser moments, generator states,
// running sums); tensors come back on the CPU.
#pragma once

#include <torch/nn/module.h>
#include <torch/types.h>

#include <map>
#include <memory>
#include <string>

#include "core/fs.h"
#include "core/status.h"

namespace headforge {

class Checkpoint {
 public:
  // An undefined tensor is stored as absent: Get() then says false.
  void Put(const std::string& name, const torch::Tensor& tensor);
  void Put(const std::string& name, int64_t value);
  void Put(const std::string& name, double value);
  // Text, stored as a tensor of its bytes.
  void PutText(const std::string& name, const std::string& text);

  // False when the name was not stored (or holds another kind of value).
  bool Get(const std::string& name, torch::Tensor* tensor) const;
  bool Get(const std::string& name, int64_t* value) const;
  bool Get(const std::string& name, double* value) const;
  bool GetText(const std::string& name, std::string* text) const;

  // Every parameter of `module` as prefix + its name; and back, copied into
  // the module's own tensors (false when one is missing or of another shape).
  void PutModule(const std::string& prefix, const torch::nn::Module& module);
  bool GetModule(const std::string& prefix, torch::nn::Module* module) const;

  Status Save(const fs::path& path) const;
  // DataError when the file is not a checkpoint (damaged, another format).
  static Status Load(const fs::path& path, Checkpoint* checkpoint);

  // The tensors alone as a .safetensors file (the portable weights export
  // writes), with `metadata` in its header.
  Status SaveSafetensors(const fs::path& path, const std::map<std::string, std::string>& metadata) const;
  // A model folder's weights: model.pt as train writes it, or, without one,
  // weights.safetensors as export does; *file says which was read.
  static Status LoadModelWeights(const fs::path& dir, Checkpoint* checkpoint, fs::path* file);

 private:
  std::map<std::string, torch::Tensor> tensors_;
  std::map<std::string, int64_t> integers_;
  std::map<std::string, double> reals_;
};

}  // namespace headforge
