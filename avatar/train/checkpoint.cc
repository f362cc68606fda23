#include "avatar/train/checkpoint.h"

#include <torch/torch.h>

#include <sstream>

#include "avatar/train/tensor_safetensors.h"
#include "core/safetensors.h"

namespace headforge {
namespace {

// The archive's keys carry the kind, so one name can be looked up by kind.
std::string Key(char kind, const std::string& name) { return std::string(1, kind) + "." + name; }

}  // namespace

void Checkpoint::Put(const std::string& name, const torch::Tensor& tensor) {
  if (tensor.defined()) {
    tensors_[name] = tensor.detach().cpu().contiguous();
  } else {
    tensors_.erase(name);
  }
}
void Checkpoint::Put(const std::string& name, int64_t value) { integers_[name] = value; }
void Checkpoint::Put(const std::string& name, double value) { reals_[name] = value; }

void Checkpoint::PutText(const std::string& name, const std::string& text) {
  tensors_[name] = torch::tensor(std::vector<uint8_t>(text.begin(), text.end()), torch::kUInt8);
}

bool Checkpoint::GetText(const std::string& name, std::string* text) const {
  const auto it = tensors_.find(name);
  if (it == tensors_.end() || it->second.scalar_type() != torch::kUInt8) return false;
  const torch::Tensor bytes = it->second.contiguous();
  text->assign(reinterpret_cast<const char*>(bytes.data_ptr<uint8_t>()), size_t(bytes.numel()));
  return true;
}

void Checkpoint::PutModule(const std::string& prefix, const torch::nn::Module& module) {
  for (const auto& item : module.named_parameters()) Put(prefix + item.key(), item.value());
}

bool Checkpoint::GetModule(const std::string& prefix, torch::nn::Module* module) const {
  torch::NoGradGuard no_grad;
  for (auto& item : module->named_parameters()) {
    const auto it = tensors_.find(prefix + item.key());
    if (it == tensors_.end() || !it->second.sizes().equals(item.value().sizes())) return false;
    item.value().copy_(it->second);
  }
  return true;
}

bool Checkpoint::Get(const std::string& name, torch::Tensor* tensor) const {
  const auto it = tensors_.find(name);
  if (it == tensors_.end()) return false;
  *tensor = it->second.clone();
  return true;
}
bool Checkpoint::Get(const std::string& name, int64_t* value) const {
  const auto it = integers_.find(name);
  if (it == integers_.end()) return false;
  *value = it->second;
  return true;
}
bool Checkpoint::Get(const std::string& name, double* value) const {
  const auto it = reals_.find(name);
  if (it == reals_.end()) return false;
  *value = it->second;
  return true;
}

Status Checkpoint::Save(const fs::path& path) const {
  std::ostringstream bytes;
  try {
    torch::serialize::OutputArchive archive;
    std::vector<std::string> names[3];
    for (const auto& [name, t] : tensors_) {
      archive.write(Key('t', name), c10::IValue(t));
      names[0].push_back(name);
    }
    for (const auto& [name, v] : integers_) {
      archive.write(Key('i', name), c10::IValue(v));
      names[1].push_back(name);
    }
    for (const auto& [name, v] : reals_) {
      archive.write(Key('r', name), c10::IValue(v));
      names[2].push_back(name);
    }
    // The archive cannot list its keys in every LibTorch version: store them.
    for (int k = 0; k < 3; ++k) {
      c10::List<std::string> list;
      for (const auto& n : names[k]) list.push_back(n);
      archive.write(Key('k', std::to_string(k)), c10::IValue(list));
    }
    archive.save_to(bytes);
  } catch (const c10::Error& e) {
    return Status::Internal("cannot serialise the checkpoint " + path.string() + ": " + e.what_without_backtrace());
  }
  return WriteFileAtomic(path, bytes.str());
}

Status Checkpoint::Load(const fs::path& path, Checkpoint* checkpoint) {
  std::string text;
  HF_RETURN_IF_ERROR(ReadFileToString(path, &text));
  Checkpoint out;
  try {
    std::istringstream bytes(text);
    torch::serialize::InputArchive archive;
    archive.load_from(bytes);
    for (int k = 0; k < 3; ++k) {
      c10::IValue list;
      archive.read(Key('k', std::to_string(k)), list);
      for (const c10::IValue& item : list.toListRef()) {
        const std::string name = item.toStringRef();
        c10::IValue value;
        archive.read(Key("tir"[k], name), value);
        if (k == 0) out.tensors_[name] = value.toTensor();
        if (k == 1) out.integers_[name] = value.toInt();
        if (k == 2) out.reals_[name] = value.toDouble();
      }
    }
  } catch (const c10::Error& e) {
    return Status::DataError(path.string() + " is not a readable checkpoint (" + e.what_without_backtrace() +
                             "); delete it to start over");
  }
  *checkpoint = std::move(out);
  return Status::Ok();
}

Status Checkpoint::SaveSafetensors(const fs::path& path, const std::map<std::string, std::string>& metadata) const {
  SafeTensorsFile file;
  file.metadata = metadata;
  try {
    for (const auto& [name, tensor] : tensors_) file.tensors.push_back(ToSafeTensor(name, tensor));
  } catch (const c10::Error& e) {
    return Status::Internal(e.what_without_backtrace());
  }
  return WriteSafetensors(path, file);
}

Status Checkpoint::LoadModelWeights(const fs::path& dir, Checkpoint* checkpoint, fs::path* file) {
  std::error_code ec;
  *file = dir / "model.pt";
  if (fs::exists(*file, ec) || !fs::exists(dir / "weights.safetensors", ec)) return Load(*file, checkpoint);
  *file = dir / "weights.safetensors";
  SafeTensorsFile safe;
  HF_RETURN_IF_ERROR(ReadSafetensors(*file, &safe));
  Checkpoint out;
  for (const SafeTensor& t : safe.tensors) {
    torch::Tensor value;
    if (!FromSafeTensor(t, &value))
      return Status::DataError(file->string() + ": " + t.name + " has a type (" + t.dtype + ") this reader does not take");
    out.Put(t.name, value);
  }
  *checkpoint = std::move(out);
  return Status::Ok();
}

}  // namespace headforge
