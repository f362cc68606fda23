#include "export/gaussian_glb.h"

#include <algorithm>
#include <cmath>

#include "export/gltf_builder.h"

namespace headforge {

namespace {

constexpr float kShC0 = 0.28209479177387814f;  // the degree-0 real spherical harmonic
constexpr size_t kAttributes = 13;            // a blendshape's attributes per Gaussian

// The KHR_gaussian_splatting primitive of `splats` in `gltf`'s model.
Status SplatPrimitive(const AvatarSplats& splats, GltfBuilder* gltf, tinygltf::Primitive* primitive) {
  const size_t n = splats.size();
  if (splats.means.size() != 3 * n || splats.rotations.size() != 4 * n || splats.scales.size() != 3 * n ||
      splats.colours.size() != 3 * n)
    return Status::InvalidArgument("Gaussian GLB: the arrays do not describe the same number of Gaussians");
  if (n == 0) return Status::InvalidArgument("Gaussian GLB: no Gaussians to write");
  std::vector<float> rotations(4 * n), sh(3 * n), colours(4 * n), opacities(n), scales(3 * n);
  for (size_t i = 0; i < n; ++i) {
    // w, x, y, z -> x, y, z, w
    rotations[4 * i + 0] = splats.rotations[4 * i + 1];
    rotations[4 * i + 1] = splats.rotations[4 * i + 2];
    rotations[4 * i + 2] = splats.rotations[4 * i + 3];
    rotations[4 * i + 3] = splats.rotations[4 * i + 0];
    opacities[i] = std::clamp(splats.opacities[i], 0.0f, 1.0f);
    for (int c = 0; c < 3; ++c) {
      const float colour = std::clamp(splats.colours[3 * i + c], 0.0f, 1.0f);
      sh[3 * i + c] = (colour - 0.5f) / kShC0;
      colours[4 * i + c] = colour;
      scales[3 * i + c] = std::max(splats.scales[3 * i + c], 0.0f);
    }
    colours[4 * i + 3] = opacities[i];
  }
  primitive->mode = TINYGLTF_MODE_POINTS;
  primitive->attributes["POSITION"] = gltf->Floats(splats.means, 3, true, TINYGLTF_TARGET_ARRAY_BUFFER);
  primitive->attributes["COLOR_0"] = gltf->Floats(colours, 4, false, TINYGLTF_TARGET_ARRAY_BUFFER);
  primitive->attributes["KHR_gaussian_splatting:ROTATION"] =
      gltf->Floats(rotations, 4, false, TINYGLTF_TARGET_ARRAY_BUFFER);
  primitive->attributes["KHR_gaussian_splatting:SCALE"] = gltf->Floats(scales, 3, false, TINYGLTF_TARGET_ARRAY_BUFFER);
  primitive->attributes["KHR_gaussian_splatting:OPACITY"] =
      gltf->Floats(opacities, 1, false, TINYGLTF_TARGET_ARRAY_BUFFER);
  primitive->attributes["KHR_gaussian_splatting:SH_DEGREE_0_COEF_0"] =
      gltf->Floats(sh, 3, false, TINYGLTF_TARGET_ARRAY_BUFFER);
  tinygltf::Value::Object extension{{"kernel", tinygltf::Value(std::string("ellipse"))},
                                    {"colorSpace", tinygltf::Value(std::string("srgb_rec709_display"))},
                                    {"projection", tinygltf::Value(std::string("perspective"))},
                                    {"sortingMethod", tinygltf::Value(std::string("cameraDistance"))}};
  primitive->extensions["KHR_gaussian_splatting"] = tinygltf::Value(extension);
  return Status::Ok();
}

// A model of one node holding `mesh`, written to `path`.
Status WriteSingleMesh(const fs::path& path, tinygltf::Mesh mesh, GltfBuilder* gltf) {
  tinygltf::Model& m = gltf->model();
  m.meshes.push_back(std::move(mesh));
  tinygltf::Node node;
  node.name = "avatar";
  node.mesh = 0;
  m.nodes.push_back(node);
  tinygltf::Scene scene;
  scene.nodes = {0};
  m.scenes.push_back(scene);
  m.defaultScene = 0;
  m.extensionsUsed.push_back("KHR_gaussian_splatting");
  return gltf->WriteGlb(path);
}

}  // namespace

Status WriteGaussianGlb(const fs::path& path, const AvatarSplats& splats) {
  GltfBuilder gltf;
  tinygltf::Primitive primitive;
  HF_RETURN_IF_ERROR(SplatPrimitive(splats, &gltf, &primitive));
  tinygltf::Mesh mesh;
  mesh.name = "gaussians";
  mesh.primitives.push_back(primitive);
  return WriteSingleMesh(path, std::move(mesh), &gltf);
}

Status WriteGaussianBlendshapeGlb(const fs::path& path, const AvatarBlendshapes& shapes) {
  const size_t n = shapes.neutral.size(), k = shapes.names.size();
  if (shapes.offsets.size() != k * n * kAttributes || shapes.neutral_attributes.size() != n * kAttributes)
    return Status::InvalidArgument("Gaussian blendshape GLB: the offsets do not match the Gaussians and names");
  GltfBuilder gltf;
  tinygltf::Primitive primitive;
  HF_RETURN_IF_ERROR(SplatPrimitive(shapes.neutral, &gltf, &primitive));
  // The neutral quaternions' lengths, by which the rotation offsets are divided.
  std::vector<float> lengths(n);
  for (size_t i = 0; i < n; ++i) {
    const float* a = &shapes.neutral_attributes[i * kAttributes];
    lengths[i] = std::max(std::sqrt(a[3] * a[3] + a[4] * a[4] + a[5] * a[5] + a[6] * a[6]), 1e-12f);
  }
  std::vector<float> position(3 * n), rotation(4 * n), scale(3 * n), sh(3 * n);
  for (size_t e = 0; e < k; ++e) {
    for (size_t i = 0; i < n; ++i) {
      const float* d = &shapes.offsets[(e * n + i) * kAttributes];
      const float length = lengths[i];
      for (int c = 0; c < 3; ++c) {
        position[3 * i + size_t(c)] = d[c];
        rotation[4 * i + size_t(c)] = d[4 + c] / length;  // x, y, z
        scale[3 * i + size_t(c)] = shapes.neutral.scales[3 * i + size_t(c)] * d[7 + c];
        sh[3 * i + size_t(c)] = d[10 + c] / kShC0;
      }
      rotation[4 * i + 3] = d[3] / length;  // w
    }
    const int rotations = gltf.Floats(rotation, 4, false, TINYGLTF_TARGET_ARRAY_BUFFER);
    primitive.targets.push_back({{"POSITION", gltf.SparseVec3(position)},
                                 {"KHR_gaussian_splatting:ROTATION", rotations},
                                 {"KHR_gaussian_splatting:SCALE", gltf.SparseVec3(scale)},
                                 {"KHR_gaussian_splatting:SH_DEGREE_0_COEF_0", gltf.SparseVec3(sh)}});
  }
  tinygltf::Mesh mesh;
  mesh.name = "gaussian_blendshapes";
  mesh.primitives.push_back(primitive);
  mesh.weights.assign(k, 0.0);
  tinygltf::Value::Array names;
  for (const std::string& name : shapes.names) names.emplace_back(name);
  mesh.extras = tinygltf::Value(tinygltf::Value::Object{{"targetNames", tinygltf::Value(names)}});
  return WriteSingleMesh(path, std::move(mesh), &gltf);
}

}  // namespace headforge
