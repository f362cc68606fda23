// Building a glTF 2.0 binary (.glb) with tinygltf: one buffer, a view per
// array (4-byte aligned), accessors with the bounds the spec asks for, and
// the file written through a temporary name.
#pragma once

#include <string>
#include <vector>

#include <tiny_gltf.h>

#include "core/fs.h"
#include "core/status.h"

namespace headforge {

class GltfBuilder {
 public:
  GltfBuilder();
  tinygltf::Model& model() { return model_; }

  // A buffer view of `bytes` bytes; `target` is 0 or a TINYGLTF_TARGET_*.
  int View(const void* data, size_t bytes, int target = 0);
  // A float accessor of `count` elements of `components` floats (1, 2, 3 or
  // 4: SCALAR, VEC2, VEC3, VEC4); with `bounds`, min and max per component.
  int Floats(const std::vector<float>& values, int components, bool bounds, int target = 0);
  // A VEC3 float accessor stored sparsely: zero except the elements whose
  // largest component exceeds `epsilon` in magnitude (morph targets, which
  // move a part of the mesh). Bounds over every element.
  int SparseVec3(const std::vector<float>& values, float epsilon = kMorphEpsilon);
  // Morph offsets at most this large (metres, log-scale units, SH
  // coefficients) are written as zero: a micrometre.
  static constexpr float kMorphEpsilon = 1e-6f;
  // An unsigned 32-bit index accessor.
  int Indices(const std::vector<uint32_t>& indices);
  // An image stored in the buffer (PNG bytes).
  int PngImage(const std::vector<unsigned char>& png, const std::string& name);

  // Writes the model as a .glb.
  Status WriteGlb(const fs::path& path);

 private:
  tinygltf::Model model_;
};

}  // namespace headforge
