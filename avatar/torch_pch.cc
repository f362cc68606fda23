// The translation unit that carries the one precompiled <torch/torch.h> every
// LibTorch target of avatar/ reuses (avatar/CMakeLists.txt).
