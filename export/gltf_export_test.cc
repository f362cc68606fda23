// The glTF writers read back by tinygltf's reader and, when node and the
// npm tools are installed, checked by Khronos' glTF-Validator.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <cstring>

#include <tiny_gltf.h>

#include <opencv2/imgcodecs.hpp>

#include "export/gaussian_glb.h"
#include "export/mesh_avatar.h"

namespace headforge {
namespace {

fs::path Temp(const std::string& name) { return fs::temp_directory_path() / ("hf_gltf_" + name); }

tinygltf::Model Load(const fs::path& path) {
  tinygltf::Model model;
  tinygltf::TinyGLTF loader;
  std::string err, warn;
  EXPECT_TRUE(loader.LoadBinaryFromFile(&model, &err, &warn, path.string())) << err;
  return model;
}

// The floats an accessor holds (tightly packed float accessors, dense or
// sparse with uint32 indices), as the specification defines them.
std::vector<float> Read(const tinygltf::Model& m, int accessor) {
  const tinygltf::Accessor& a = m.accessors[size_t(accessor)];
  EXPECT_EQ(a.componentType, TINYGLTF_COMPONENT_TYPE_FLOAT);
  const int components = tinygltf::GetNumComponentsInType(uint32_t(a.type));
  std::vector<float> out(a.count * size_t(components), 0.0f);
  const auto bytes = [&](int view, size_t offset) {
    const tinygltf::BufferView& v = m.bufferViews[size_t(view)];
    return m.buffers[size_t(v.buffer)].data.data() + v.byteOffset + offset;
  };
  if (a.bufferView >= 0) std::memcpy(out.data(), bytes(a.bufferView, a.byteOffset), out.size() * 4);
  if (a.sparse.isSparse) {
    EXPECT_EQ(a.sparse.indices.componentType, TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT);
    const auto* indices = reinterpret_cast<const uint32_t*>(bytes(a.sparse.indices.bufferView, size_t(a.sparse.indices.byteOffset)));
    const auto* values = reinterpret_cast<const float*>(bytes(a.sparse.values.bufferView, size_t(a.sparse.values.byteOffset)));
    for (int i = 0; i < a.sparse.count; ++i)
      for (int c = 0; c < components; ++c) out[size_t(indices[i]) * size_t(components) + size_t(c)] = values[i * components + c];
  }
  return out;
}

#ifdef HEADFORGE_GLTF_VALIDATOR
// Khronos' validator: exit code 0 when it reports no error.
int Validate(const fs::path& file, const std::string& extra = "") {
  const std::string command = std::string("'") + HEADFORGE_NODE + "' '" + HEADFORGE_VALIDATE_SCRIPT + "' '" +
                              file.string() + "' --validator '" + HEADFORGE_GLTF_VALIDATOR + "' " + extra;
  return std::system(command.c_str());
}
#endif

TEST(MeshAvatarGltf, BlendshapeNamesAreArkitStyle) {
  EXPECT_EQ(ArkitName("eyeBlink_L"), "eyeBlinkLeft");
  EXPECT_EQ(ArkitName("mouthSmile_R"), "mouthSmileRight");
  EXPECT_EQ(ArkitName("jawOpen"), "jawOpen");
  EXPECT_EQ(ArkitName("_L"), "_L");
}

// A tetrahedron with two morph targets and three frames of animation.
MeshAvatar SmallAvatar() {
  MeshAvatar a;
  a.positions.resize(3, 4);
  a.positions << 0, 0.1f, 0, 0, 0, 0, 0.1f, 0, 0, 0, 0, 0.1f;
  a.texcoords.resize(2, 4);
  a.texcoords << 0.1f, 0.9f, 0.1f, 0.5f, 0.1f, 0.1f, 0.9f, 0.5f;
  a.triangles.resize(3, 4);
  a.triangles << 0, 0, 0, 1, 2, 1, 3, 2, 1, 3, 2, 3;
  a.source_vertex = {0, 1, 2, 3};
  Eigen::Matrix3Xf t0 = Eigen::Matrix3Xf::Zero(3, 4), t1 = Eigen::Matrix3Xf::Zero(3, 4);
  t0(1, 3) = 0.02f;
  t1(0, 1) = -0.03f;
  a.targets = {t0, t1};
  a.target_names = {"jawOpen", "eyeBlinkLeft"};
  a.texture = cv::Mat(8, 8, CV_8UC3);
  cv::randu(a.texture, 0, 255);
  a.times = {0, 0.04, 0.08};
  for (int f = 0; f < 3; ++f) {
    a.weights.push_back(Eigen::Vector2f(0.3f * f, 1.0f - 0.4f * f));
    Eigen::Isometry3d motion = Eigen::Isometry3d::Identity();
    motion.linear() = Eigen::AngleAxisd(0.2 * f, Eigen::Vector3d(0.3, 1, 0.1).normalized()).toRotationMatrix();
    motion.translation() = Eigen::Vector3d(0.01 * f, -0.02 * f, 0.005);
    a.head_motion.push_back(motion);
  }
  a.yfov = 0.4;
  a.aspect = 1.5;
  return a;
}

TEST(MeshAvatarGltf, ReadBackTheAnimationGivesTheTrackedVertices) {
  const MeshAvatar avatar = SmallAvatar();
  ASSERT_TRUE(WriteMeshAvatarGlb(Temp("mesh.glb"), avatar).ok());
  const tinygltf::Model m = Load(Temp("mesh.glb"));
  ASSERT_EQ(m.meshes.size(), 1u);
  const tinygltf::Primitive& p = m.meshes[0].primitives[0];
  ASSERT_EQ(p.targets.size(), 2u);
  EXPECT_TRUE(m.accessors[size_t(p.targets[0].at("POSITION"))].sparse.isSparse);
  EXPECT_EQ(m.accessors[size_t(p.targets[0].at("POSITION"))].sparse.count, 1);
  const tinygltf::Value& names = m.meshes[0].extras.Get("targetNames");
  ASSERT_TRUE(names.IsArray());
  EXPECT_EQ(names.Get(0).Get<std::string>(), "jawOpen");
  EXPECT_EQ(names.Get(1).Get<std::string>(), "eyeBlinkLeft");
  EXPECT_NEAR(m.cameras[0].perspective.yfov, 0.4, 1e-12);

  // Every frame: base + weights x targets, then the node's rotation and
  // translation from the animation, as a viewer computes it.
  const std::vector<float> base = Read(m, p.attributes.at("POSITION"));
  const std::vector<float> d0 = Read(m, p.targets[0].at("POSITION")), d1 = Read(m, p.targets[1].at("POSITION"));
  const tinygltf::Animation& anim = m.animations[0];
  std::map<std::string, std::vector<float>> outputs;
  std::vector<float> times;
  for (const tinygltf::AnimationChannel& c : anim.channels) {
    EXPECT_EQ(c.target_node, 0);
    const tinygltf::AnimationSampler& s = anim.samplers[size_t(c.sampler)];
    outputs[c.target_path] = Read(m, s.output);
    times = Read(m, s.input);
  }
  ASSERT_EQ(times.size(), 3u);
  EXPECT_FLOAT_EQ(times[2], 0.08f);
  for (int f = 0; f < 3; ++f) {
    const float* w = &outputs["weights"][size_t(2 * f)];
    const float* q = &outputs["rotation"][size_t(4 * f)];
    const float* t = &outputs["translation"][size_t(3 * f)];
    const Eigen::Matrix3f r = Eigen::Quaternionf(q[3], q[0], q[1], q[2]).toRotationMatrix();
    const Eigen::Matrix3Xf expected = MeshAvatarVertices(avatar, f);
    for (int v = 0; v < 4; ++v) {
      Eigen::Vector3f x;
      for (int d = 0; d < 3; ++d) x[d] = base[size_t(3 * v + d)] + w[0] * d0[size_t(3 * v + d)] + w[1] * d1[size_t(3 * v + d)];
      const Eigen::Vector3f shown = r * x + Eigen::Vector3f(t[0], t[1], t[2]);
      EXPECT_LT((shown - expected.col(v)).norm(), 1e-6f) << "frame " << f << " vertex " << v;
    }
  }
  // The texture comes back pixel for pixel (PNG).
  const tinygltf::Image& image = m.images[0];
  const tinygltf::BufferView& view = m.bufferViews[size_t(image.bufferView)];
  const std::vector<unsigned char> png(m.buffers[0].data.begin() + std::ptrdiff_t(view.byteOffset),
                                       m.buffers[0].data.begin() + std::ptrdiff_t(view.byteOffset + view.byteLength));
  const cv::Mat decoded = cv::imdecode(png, cv::IMREAD_COLOR);
  ASSERT_EQ(decoded.size(), avatar.texture.size());
  EXPECT_EQ(cv::norm(decoded, avatar.texture, cv::NORM_INF), 0.0);
#ifdef HEADFORGE_GLTF_VALIDATOR
  EXPECT_EQ(Validate(Temp("mesh.glb")), 0);
#endif
}

TEST(GaussianGltf, AttributesFollowKhrGaussianSplatting) {
  AvatarSplats s;
  s.means = {0, 0, 0, 0.1f, -0.2f, 0.3f};
  s.rotations = {1, 0, 0, 0, 0.5f, 0.5f, -0.5f, 0.5f};  // w, x, y, z
  s.scales = {0.01f, 0.02f, 0.03f, 0.001f, 0.001f, 0.004f};
  s.opacities = {0.25f, 0.99f};
  s.colours = {0.5f, 0.0f, 1.0f, 0.2f, 0.4f, 0.6f};
  ASSERT_TRUE(WriteGaussianGlb(Temp("splats.glb"), s).ok());
  const tinygltf::Model m = Load(Temp("splats.glb"));
  ASSERT_EQ(m.extensionsUsed, std::vector<std::string>{"KHR_gaussian_splatting"});
  const tinygltf::Primitive& p = m.meshes[0].primitives[0];
  EXPECT_EQ(p.mode, TINYGLTF_MODE_POINTS);
  const tinygltf::Value& ext = p.extensions.at("KHR_gaussian_splatting");
  EXPECT_EQ(ext.Get("kernel").Get<std::string>(), "ellipse");
  EXPECT_EQ(ext.Get("colorSpace").Get<std::string>(), "srgb_rec709_display");
  const std::vector<float> rotation = Read(m, p.attributes.at("KHR_gaussian_splatting:ROTATION"));
  const std::vector<float> scale = Read(m, p.attributes.at("KHR_gaussian_splatting:SCALE"));
  const std::vector<float> opacity = Read(m, p.attributes.at("KHR_gaussian_splatting:OPACITY"));
  const std::vector<float> sh = Read(m, p.attributes.at("KHR_gaussian_splatting:SH_DEGREE_0_COEF_0"));
  const std::vector<float> position = Read(m, p.attributes.at("POSITION"));
  EXPECT_EQ(position, s.means);
  // x, y, z, w; linear scales; opacities after the sigmoid; colour = 0.5 + C0 sh.
  EXPECT_EQ(rotation, (std::vector<float>{0, 0, 0, 1, 0.5f, -0.5f, 0.5f, 0.5f}));
  EXPECT_EQ(scale, s.scales);
  EXPECT_EQ(opacity, s.opacities);
  for (size_t i = 0; i < sh.size(); ++i) EXPECT_NEAR(0.5f + 0.28209479f * sh[i], s.colours[i], 1e-6f);
  const std::vector<double>& lo = m.accessors[size_t(p.attributes.at("POSITION"))].minValues;
  EXPECT_EQ(lo, (std::vector<double>{0, -0.2f, 0}));
#ifdef HEADFORGE_GLTF_VALIDATOR
  EXPECT_EQ(Validate(Temp("splats.glb"), "--extension-attributes KHR_gaussian_splatting"), 0);
#endif
}

// Two Gaussians, two expressions: a morph target each, named, holding each
// attribute's offset as the header comment gives it; one target moves every
// Gaussian down (all its stored values negative: the bounds are theirs).
TEST(GaussianGltf, BlendshapesAreMorphTargetsNamedAfterTheExpressions) {
  AvatarBlendshapes b;
  b.neutral.means = {0, 0, 0, 0.1f, -0.2f, 0.3f};
  b.neutral.rotations = {1, 0, 0, 0, 0, 0, 0, 1};
  b.neutral.scales = {0.01f, 0.02f, 0.03f, 0.001f, 0.001f, 0.004f};
  b.neutral.opacities = {0.25f, 0.99f};
  b.neutral.colours = {0.5f, 0.0f, 1.0f, 0.2f, 0.4f, 0.6f};
  b.names = {"jawOpen", "eyeBlink_L"};
  // Before normalising: the first rotation has length 2, the second 1.
  b.neutral_attributes = {0, 0, 0, 2, 0, 0, 0, std::log(0.01f), std::log(0.02f), std::log(0.03f), 0.5f, 0, 1,
                          0.1f, -0.2f, 0.3f, 0, 0, 0, 1, std::log(0.001f), std::log(0.001f), std::log(0.004f), 0.2f,
                          0.4f, 0.6f};
  b.offsets.assign(2 * 2 * 13, 0.0f);
  auto offset = [&](int e, int i, int a) -> float& { return b.offsets[size_t((e * 2 + i) * 13 + a)]; };
  offset(0, 0, 1) = -0.01f;  // jawOpen: both down, the first turned, the second redder and wider
  offset(0, 1, 1) = -0.02f;
  offset(0, 0, 4) = 0.2f;    // x of (w, x, y, z)
  offset(0, 1, 10) = 0.1f;
  offset(0, 1, 7) = 0.5f;    // log-scale x
  offset(1, 1, 2) = 0.005f;  // eyeBlink_L: the second forward
  ASSERT_TRUE(WriteGaussianBlendshapeGlb(Temp("blendshapes.glb"), b).ok());
  const tinygltf::Model m = Load(Temp("blendshapes.glb"));
  const tinygltf::Mesh& mesh = m.meshes[0];
  const tinygltf::Primitive& p = mesh.primitives[0];
  ASSERT_EQ(p.targets.size(), 2u);
  EXPECT_EQ(mesh.weights, (std::vector<double>{0, 0}));
  EXPECT_EQ(mesh.extras.Get("targetNames").Get(0).Get<std::string>(), "jawOpen");
  EXPECT_EQ(mesh.extras.Get("targetNames").Get(1).Get<std::string>(), "eyeBlink_L");
  EXPECT_EQ(Read(m, p.attributes.at("POSITION")), b.neutral.means);
  const auto& jaw = p.targets[0];
  EXPECT_EQ(Read(m, jaw.at("POSITION")), (std::vector<float>{0, -0.01f, 0, 0, -0.02f, 0}));
  EXPECT_EQ(m.accessors[size_t(jaw.at("POSITION"))].maxValues, (std::vector<double>{0, double(-0.01f), 0}));
  // x, y, z, w over the neutral quaternion's length (2 for the first).
  EXPECT_EQ(Read(m, jaw.at("KHR_gaussian_splatting:ROTATION")), (std::vector<float>{0.1f, 0, 0, 0, 0, 0, 0, 0}));
  const std::vector<float> scale = Read(m, jaw.at("KHR_gaussian_splatting:SCALE"));
  EXPECT_NEAR(scale[3], 0.001f * 0.5f, 1e-9f);  // linearised at the neutral scale
  const std::vector<float> sh = Read(m, jaw.at("KHR_gaussian_splatting:SH_DEGREE_0_COEF_0"));
  EXPECT_NEAR(0.28209479f * sh[3], 0.1f, 1e-6f);
  EXPECT_EQ(Read(m, p.targets[1].at("POSITION")), (std::vector<float>{0, 0, 0, 0, 0, 0.005f}));
  b.offsets.pop_back();
  EXPECT_FALSE(WriteGaussianBlendshapeGlb(Temp("bad_blendshapes.glb"), b).ok());
#ifdef HEADFORGE_GLTF_VALIDATOR
  EXPECT_EQ(Validate(Temp("blendshapes.glb"), "--extension-attributes KHR_gaussian_splatting"), 0);
#endif
}

TEST(GaussianGltf, MismatchedArraysAreRefused) {
  AvatarSplats s;
  s.means = {0, 0, 0};
  s.opacities = {0.5f};
  EXPECT_FALSE(WriteGaussianGlb(Temp("bad.glb"), s).ok());
  EXPECT_FALSE(WriteGaussianGlb(Temp("empty.glb"), AvatarSplats()).ok());
}

}  // namespace
}  // namespace headforge
