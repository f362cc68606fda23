#include "avatar/train/device.h"

#include <torch/cuda.h>

namespace headforge {

Status ParseDevice(const std::string& who, const std::string& name, torch::Device* device) {
  try {
    *device = torch::Device(name);
  } catch (const c10::Error&) {
    return Status::InvalidArgument(who + ": '" + name + "' is not a device (try cpu or cuda)");
  }
  if (device->is_cpu()) return Status::Ok();
  if (!device->is_cuda()) return Status::InvalidArgument(who + ": no kernels for device " + name + " (cpu or cuda)");
  if (!torch::cuda::is_available())
    return Status::InvalidArgument(who + ": device " + name +
                                   ": LibTorch sees no CUDA device (this build's LibTorch may be CPU-only; "
                                   "`headforge version` says which); use --device cpu");
  return Status::Ok();
}

}  // namespace headforge
