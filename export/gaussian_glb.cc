#include "export/gaussian_glb.h"

#include <algorithm>

#include "export/gltf_builder.h"

namespace headforge {

namespace {
constexpr float kShC0 = 0.28209479177387814f;  // the degree-0 real spherical harmonic
}  // namespace

Status WriteGaussianGlb(const fs::path& path, const AvatarSplats& splats) {
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
  GltfBuilder gltf;
  tinygltf::Model& m = gltf.model();
  tinygltf::Primitive primitive;
  primitive.mode = TINYGLTF_MODE_POINTS;
  primitive.attributes["POSITION"] = gltf.Floats(splats.means, 3, true, TINYGLTF_TARGET_ARRAY_BUFFER);
  primitive.attributes["COLOR_0"] = gltf.Floats(colours, 4, false, TINYGLTF_TARGET_ARRAY_BUFFER);
  primitive.attributes["KHR_gaussian_splatting:ROTATION"] = gltf.Floats(rotations, 4, false, TINYGLTF_TARGET_ARRAY_BUFFER);
  primitive.attributes["KHR_gaussian_splatting:SCALE"] = gltf.Floats(scales, 3, false, TINYGLTF_TARGET_ARRAY_BUFFER);
  primitive.attributes["KHR_gaussian_splatting:OPACITY"] = gltf.Floats(opacities, 1, false, TINYGLTF_TARGET_ARRAY_BUFFER);
  primitive.attributes["KHR_gaussian_splatting:SH_DEGREE_0_COEF_0"] =
      gltf.Floats(sh, 3, false, TINYGLTF_TARGET_ARRAY_BUFFER);
  tinygltf::Value::Object extension{{"kernel", tinygltf::Value(std::string("ellipse"))},
                                    {"colorSpace", tinygltf::Value(std::string("srgb_rec709_display"))},
                                    {"projection", tinygltf::Value(std::string("perspective"))},
                                    {"sortingMethod", tinygltf::Value(std::string("cameraDistance"))}};
  primitive.extensions["KHR_gaussian_splatting"] = tinygltf::Value(extension);
  tinygltf::Mesh mesh;
  mesh.name = "gaussians";
  mesh.primitives.push_back(primitive);
  m.meshes.push_back(mesh);
  tinygltf::Node node;
  node.name = "avatar";
  node.mesh = 0;
  m.nodes.push_back(node);
  tinygltf::Scene scene;
  scene.nodes = {0};
  m.scenes.push_back(scene);
  m.defaultScene = 0;
  m.extensionsUsed.push_back("KHR_gaussian_splatting");
  return gltf.WriteGlb(path);
}

}  // namespace headforge
