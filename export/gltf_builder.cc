#include "export/gltf_builder.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

namespace headforge {

GltfBuilder::GltfBuilder() {
  model_.asset.version = "2.0";
  model_.asset.generator = "HeadForge";
  model_.buffers.emplace_back();
}

int GltfBuilder::View(const void* data, size_t bytes, int target) {
  std::vector<unsigned char>& buffer = model_.buffers[0].data;
  buffer.resize((buffer.size() + 3) / 4 * 4, 0);  // every view starts 4-byte aligned
  tinygltf::BufferView view;
  view.buffer = 0;
  view.byteOffset = buffer.size();
  view.byteLength = bytes;
  view.target = target;
  const auto* begin = static_cast<const unsigned char*>(data);
  buffer.insert(buffer.end(), begin, begin + bytes);
  model_.bufferViews.push_back(view);
  return int(model_.bufferViews.size()) - 1;
}

int GltfBuilder::Floats(const std::vector<float>& values, int components, bool bounds, int target) {
  static const int kTypes[] = {0, TINYGLTF_TYPE_SCALAR, TINYGLTF_TYPE_VEC2, TINYGLTF_TYPE_VEC3, TINYGLTF_TYPE_VEC4};
  tinygltf::Accessor accessor;
  accessor.bufferView = View(values.data(), values.size() * sizeof(float), target);
  accessor.componentType = TINYGLTF_COMPONENT_TYPE_FLOAT;
  accessor.type = kTypes[components];
  accessor.count = values.size() / size_t(components);
  if (bounds) {
    accessor.minValues.assign(size_t(components), std::numeric_limits<double>::infinity());
    accessor.maxValues.assign(size_t(components), -std::numeric_limits<double>::infinity());
    for (size_t i = 0; i < values.size(); ++i) {
      const size_t c = i % size_t(components);
      accessor.minValues[c] = std::min(accessor.minValues[c], double(values[i]));
      accessor.maxValues[c] = std::max(accessor.maxValues[c], double(values[i]));
    }
    if (values.empty()) accessor.minValues.assign(size_t(components), 0), accessor.maxValues.assign(size_t(components), 0);
  }
  model_.accessors.push_back(accessor);
  return int(model_.accessors.size()) - 1;
}

int GltfBuilder::SparseVec3(const std::vector<float>& values, float epsilon) {
  std::vector<uint32_t> indices;
  std::vector<float> kept;
  tinygltf::Accessor accessor;
  // Bounds over the elements as stored: the kept ones, and zero when any is
  // left out.
  accessor.minValues.assign(3, std::numeric_limits<double>::infinity());
  accessor.maxValues.assign(3, -std::numeric_limits<double>::infinity());
  bool zero = false;
  for (size_t i = 0; i + 2 < values.size(); i += 3) {
    const float* v = &values[i];
    if (std::max({std::abs(v[0]), std::abs(v[1]), std::abs(v[2])}) <= epsilon) {
      zero = true;
      continue;
    }
    indices.push_back(uint32_t(i / 3));
    kept.insert(kept.end(), v, v + 3);
    for (int c = 0; c < 3; ++c) {
      accessor.minValues[size_t(c)] = std::min(accessor.minValues[size_t(c)], double(v[c]));
      accessor.maxValues[size_t(c)] = std::max(accessor.maxValues[size_t(c)], double(v[c]));
    }
  }
  if (indices.empty()) {  // the specification wants at least one sparse element
    indices.push_back(0);
    kept.assign(3, 0.0f);
  }
  for (size_t c = 0; c < 3; ++c) {
    if (zero || !std::isfinite(accessor.minValues[c])) accessor.minValues[c] = std::min(accessor.minValues[c], 0.0);
    if (zero || !std::isfinite(accessor.maxValues[c])) accessor.maxValues[c] = std::max(accessor.maxValues[c], 0.0);
  }
  accessor.bufferView = -1;  // every element zero but the sparse ones
  accessor.componentType = TINYGLTF_COMPONENT_TYPE_FLOAT;
  accessor.type = TINYGLTF_TYPE_VEC3;
  accessor.count = values.size() / 3;
  accessor.sparse.isSparse = true;
  accessor.sparse.count = int(indices.size());
  accessor.sparse.indices.bufferView = View(indices.data(), indices.size() * sizeof(uint32_t));
  accessor.sparse.indices.byteOffset = 0;
  accessor.sparse.indices.componentType = TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT;
  accessor.sparse.values.bufferView = View(kept.data(), kept.size() * sizeof(float));
  accessor.sparse.values.byteOffset = 0;
  model_.accessors.push_back(accessor);
  return int(model_.accessors.size()) - 1;
}

int GltfBuilder::Indices(const std::vector<uint32_t>& indices) {
  tinygltf::Accessor accessor;
  accessor.bufferView = View(indices.data(), indices.size() * sizeof(uint32_t), TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER);
  accessor.componentType = TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT;
  accessor.type = TINYGLTF_TYPE_SCALAR;
  accessor.count = indices.size();
  model_.accessors.push_back(accessor);
  return int(model_.accessors.size()) - 1;
}

int GltfBuilder::PngImage(const std::vector<unsigned char>& png, const std::string& name) {
  tinygltf::Image image;
  image.name = name;
  image.bufferView = View(png.data(), png.size());
  image.mimeType = "image/png";
  model_.images.push_back(image);
  return int(model_.images.size()) - 1;
}

Status GltfBuilder::WriteGlb(const fs::path& path) {
  std::ostringstream stream;
  tinygltf::TinyGLTF writer;
  if (!writer.WriteGltfSceneToStream(&model_, stream, /*prettyPrint=*/false, /*writeBinary=*/true))
    return Status::Internal("cannot serialise " + path.string() + " as glTF");
  return WriteFileAtomic(path, stream.str());
}

}  // namespace headforge
