// The training pack: a dataset goes to the file and comes back exactly (the
// 8-bit images, the cameras to the last bit, the split, the mesh), and a file
// that is not a pack, a damaged one and another version are refused by name.
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <fstream>

#include "avatar/train/dataset_pack.h"
#include "core/safetensors.h"

namespace headforge {
namespace {

fs::path Scratch(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("hf_pack_" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

AvatarView RandomView(int frame, int w, int h, bool uv, at::Generator& gen) {
  AvatarView v;
  v.frame = frame;
  v.time_s = frame / 25.0 + 1e-9 * frame;
  v.camera = frame % 2 ? "cam1" : "cam0";
  v.image = ImageFromBytes(torch::randint(0, 256, {3, h, w}, gen, torch::kUInt8));
  v.mask = ImageFromBytes(torch::randint(0, 2, {1, h, w}, gen, torch::kUInt8) * 255);
  v.condition = torch::randn({7}, gen);
  for (size_t i = 0; i < 12; ++i) v.view.cam_from_world[i] = torch::randn({1}, gen, torch::kFloat64).item<double>();
  v.view.fx = 101.0 / 3;
  v.view.fy = 102.0 / 7;
  v.view.cx = w / 2.0 - 0.1;
  v.view.cy = h / 2.0 + 1.0 / 3;
  v.view.width = w;
  v.view.height = h;
  v.regions = {{{1.f / 3, 2, 3, 4}, {5, 6, 7, 8}, {9, 10, 11, 12.5f}}};
  v.has_landmarks = frame != 2;
  v.unreliable = frame == 3;
  if (uv) v.uv_map = torch::randint(0, 256, {3, 16, 16}, gen, torch::kUInt8);
  return v;
}

AvatarDataset RandomDataset() {
  auto gen = at::detail::createCPUGenerator(5);
  AvatarDataset d;
  d.width = 12;
  d.height = 10;
  d.num_frames = 6;
  d.first_test_frame = 4;
  d.holdout_every = 3;
  for (int f = 0; f < 4; ++f) d.train.push_back(RandomView(f, 12, 10, true, gen));
  for (int f = 4; f < 6; ++f) d.test.push_back(RandomView(f, 12, 10, false, gen));
  d.expression_names = {"jawOpen", "eyeBlink_L", "eyeBlink_R", "mouthSmile_L"};
  d.identity_vertices = torch::randn({5, 3}, gen);
  d.expression_basis = torch::randn({15, 4}, gen);
  d.triangles = torch::tensor({0, 1, 2, 2, 3, 4}, torch::kInt64).view({2, 3});
  d.mesh_parts = {{"face", {0, 0}}, {"head_and_neck", {1, 1}}};
  return d;
}

void ExpectSameView(const AvatarView& a, const AvatarView& b) {
  EXPECT_EQ(a.frame, b.frame);
  EXPECT_EQ(a.time_s, b.time_s);
  EXPECT_EQ(a.camera, b.camera);
  EXPECT_TRUE(torch::equal(a.image, b.image));
  EXPECT_TRUE(torch::equal(a.mask, b.mask));
  EXPECT_TRUE(b.image.is_contiguous());
  EXPECT_TRUE(torch::equal(a.condition, b.condition));
  EXPECT_EQ(a.view.cam_from_world, b.view.cam_from_world);
  EXPECT_EQ(a.view.fx, b.view.fx);
  EXPECT_EQ(a.view.fy, b.view.fy);
  EXPECT_EQ(a.view.cx, b.view.cx);
  EXPECT_EQ(a.view.cy, b.view.cy);
  EXPECT_EQ(a.view.width, b.view.width);
  EXPECT_EQ(a.view.height, b.view.height);
  EXPECT_EQ(a.regions, b.regions);
  EXPECT_EQ(a.has_landmarks, b.has_landmarks);
  EXPECT_EQ(a.unreliable, b.unreliable);
  ASSERT_EQ(a.uv_map.defined(), b.uv_map.defined());
  if (a.uv_map.defined()) {
    EXPECT_TRUE(torch::equal(a.uv_map, b.uv_map));
  }
}

TEST(DatasetPack, ADatasetComesBackExactlyWithItsOptions) {
  const fs::path dir = Scratch("round_trip");
  const AvatarDataset data = RandomDataset();
  const nlohmann::json options = {{"model", "gaussian-style"}, {"resolution", 12}, {"lr_network", 1.0 / 3}};
  ASSERT_TRUE(WriteDatasetPack(data, options, dir / "a.pack").ok());
  AvatarDataset back;
  nlohmann::json recorded;
  const Status read = ReadDatasetPack(dir / "a.pack", &back, &recorded);
  ASSERT_TRUE(read.ok()) << read.message();
  EXPECT_EQ(recorded, options);
  EXPECT_EQ(back.width, 12);
  EXPECT_EQ(back.height, 10);
  EXPECT_EQ(back.num_frames, 6);
  EXPECT_EQ(back.first_test_frame, 4);
  EXPECT_EQ(back.holdout_every, 3);
  EXPECT_EQ(back.expression_names, data.expression_names);
  EXPECT_EQ(back.mesh_parts, data.mesh_parts);
  EXPECT_TRUE(torch::equal(back.identity_vertices, data.identity_vertices));
  EXPECT_TRUE(torch::equal(back.expression_basis, data.expression_basis));
  EXPECT_TRUE(torch::equal(back.triangles, data.triangles));
  ASSERT_EQ(back.train.size(), 4u);
  ASSERT_EQ(back.test.size(), 2u);
  for (size_t i = 0; i < 4; ++i) ExpectSameView(data.train[i], back.train[i]);
  for (size_t i = 0; i < 2; ++i) ExpectSameView(data.test[i], back.test[i]);
  // Written twice, the same bytes.
  ASSERT_TRUE(WriteDatasetPack(back, recorded, dir / "b.pack").ok());
  std::ifstream a(dir / "a.pack", std::ios::binary), b(dir / "b.pack", std::ios::binary);
  EXPECT_TRUE(std::equal(std::istreambuf_iterator<char>(a), {}, std::istreambuf_iterator<char>(b)));
  fs::remove_all(dir);
}

// The identity plus the basis times the view's expression, in doubles, one
// number at a time: [V, 3].
torch::Tensor PlainVertices(const AvatarDataset& d, const AvatarView& v) {
  const int64_t n = d.identity_vertices.size(0), e = int64_t(d.expression_names.size());
  torch::Tensor out = torch::zeros({n, 3}, torch::kFloat64);
  for (int64_t i = 0; i < n; ++i)
    for (int64_t c = 0; c < 3; ++c) {
      double x = d.identity_vertices[i][c].item<double>();
      for (int64_t k = 0; k < e; ++k)
        x += d.expression_basis[3 * i + c][k].item<double>() * v.condition[k].item<double>();
      out[i][c] = x;
    }
  return out;
}

TEST(DatasetPack, EachViewCarriesItsFramesMeshAndAPackGivesTheSame) {
  AvatarDataset data = RandomDataset();
  // A second camera's view of frame 1: the same instant, the same mesh.
  AvatarView other = data.train[1];
  other.camera = "cam2";
  data.train.push_back(other);
  AttachViewVertices(&data);
  for (const auto* list : {&data.train, &data.test})
    for (const AvatarView& v : *list) {
      ASSERT_TRUE(v.vertices.defined());
      EXPECT_EQ(v.vertices.sizes(), (std::vector<int64_t>{5, 3}));
      EXPECT_TRUE(torch::allclose(v.vertices.to(torch::kFloat64), PlainVertices(data, v), 1e-5, 1e-5)) << v.frame;
      EXPECT_TRUE(torch::allclose(data.Vertices(v.condition.slice(0, 0, 4)), v.vertices, 1e-5, 1e-5));
      EXPECT_TRUE(data.Vertices(v).is_same(v.vertices));
    }
  EXPECT_EQ(data.train[1].vertices.data_ptr(), data.train.back().vertices.data_ptr());
  EXPECT_NE(data.train[0].vertices.data_ptr(), data.train[1].vertices.data_ptr());
  // The views' meshes are not in the pack: read back, the same computation
  // gives the same numbers.
  const fs::path dir = Scratch("vertices");
  ASSERT_TRUE(WriteDatasetPack(data, nlohmann::json::object(), dir / "a.pack").ok());
  AvatarDataset back;
  nlohmann::json recorded;
  ASSERT_TRUE(ReadDatasetPack(dir / "a.pack", &back, &recorded).ok());
  ASSERT_EQ(back.train.size(), data.train.size());
  for (size_t i = 0; i < data.train.size(); ++i) EXPECT_TRUE(torch::equal(back.train[i].vertices, data.train[i].vertices));
  for (size_t i = 0; i < data.test.size(); ++i) EXPECT_TRUE(torch::equal(back.test[i].vertices, data.test[i].vertices));
  fs::remove_all(dir);
  // A mesh already set stays; one state of the head: one mesh for every view.
  AvatarDataset still = RandomDataset();
  still.one_state = true;
  const torch::Tensor given = torch::zeros({5, 3});
  still.test[0].vertices = given;
  AttachViewVertices(&still);
  EXPECT_TRUE(still.test[0].vertices.is_same(given));
  for (const AvatarView& v : still.train) EXPECT_EQ(v.vertices.data_ptr(), still.train[0].vertices.data_ptr());
  EXPECT_TRUE(torch::allclose(still.train[0].vertices.to(torch::kFloat64), PlainVertices(still, still.train[0]), 1e-5, 1e-5));
}

TEST(DatasetPack, OtherFilesAreRefusedByName) {
  const fs::path dir = Scratch("refused");
  AvatarDataset back;
  nlohmann::json recorded;
  // Weights, not a pack.
  SafeTensorsFile weights;
  const float one = 1;
  weights.tensors.push_back(SafeTensor::Float32("w", {1}, &one));
  ASSERT_TRUE(WriteSafetensors(dir / "weights.safetensors", weights).ok());
  Status s = ReadDatasetPack(dir / "weights.safetensors", &back, &recorded);
  EXPECT_EQ(s.code(), Status::Code::kDataError);
  EXPECT_NE(s.message().find("not a training pack"), std::string::npos) << s.message();
  // A pack cut short.
  ASSERT_TRUE(WriteDatasetPack(RandomDataset(), nlohmann::json::object(), dir / "a.pack").ok());
  fs::resize_file(dir / "a.pack", fs::file_size(dir / "a.pack") - 100);
  s = ReadDatasetPack(dir / "a.pack", &back, &recorded);
  EXPECT_EQ(s.code(), Status::Code::kDataError) << s.message();
  // Another version.
  SafeTensorsFile pack;
  ASSERT_TRUE(WriteDatasetPack(RandomDataset(), nlohmann::json::object(), dir / "b.pack").ok());
  ASSERT_TRUE(ReadSafetensors(dir / "b.pack", &pack).ok());
  pack.metadata["version"] = "99";
  ASSERT_TRUE(WriteSafetensors(dir / "c.pack", pack).ok());
  s = ReadDatasetPack(dir / "c.pack", &back, &recorded);
  EXPECT_EQ(s.code(), Status::Code::kDataError);
  EXPECT_NE(s.message().find("version 99"), std::string::npos) << s.message();
  // A view's image missing from the tensors.
  pack.metadata["version"] = "1";
  pack.tensors.erase(std::remove_if(pack.tensors.begin(), pack.tensors.end(),
                                    [](const SafeTensor& t) { return t.name == "view.3.image"; }),
                     pack.tensors.end());
  ASSERT_TRUE(WriteSafetensors(dir / "d.pack", pack).ok());
  s = ReadDatasetPack(dir / "d.pack", &back, &recorded);
  EXPECT_EQ(s.code(), Status::Code::kDataError);
  EXPECT_NE(s.message().find("damaged"), std::string::npos) << s.message();
  fs::remove_all(dir);
}

}  // namespace
}  // namespace headforge
