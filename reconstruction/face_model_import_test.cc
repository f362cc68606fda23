#include "reconstruction/face_model_import.h"

#include <gtest/gtest.h>
#include <H5Cpp.h>

#include <Eigen/Geometry>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include "core/face_model.h"
#include "core/fs.h"
#include "reconstruction/pose_identity.h"

namespace headforge {
namespace {

// A fresh folder named after the running test.
fs::path ScratchDir() {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  const fs::path dir =
      fs::temp_directory_path() / ("hf_" + std::string(info->test_suite_name()) + "_" + info->name());
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

void WriteText(const fs::path& path, const std::string& text) {
  std::ofstream out(path);
  out << text;
  ASSERT_TRUE(out.good()) << path;
}

// A small ICT-like model folder: a 4 x 3 grid of vertices (6 quads) in
// centimetres with one texture coordinate per vertex, listed in reverse
// order so that vertex and UV indices differ.
constexpr int kColumns = 4, kRows = 3, kVertices = kColumns * kRows, kQuads = (kColumns - 1) * (kRows - 1);
constexpr int kIdentities = 3;
const std::vector<std::string> kExpressions = {"jawOpen", "eyeBlink_L", "mouthSmile_R", "cheekPuff_L"};

Eigen::Matrix3Xd NeutralCm() {
  Eigen::Matrix3Xd v(3, kVertices);
  for (int j = 0; j < kRows; ++j)
    for (int i = 0; i < kColumns; ++i) v.col(j * kColumns + i) << 2.0 * i - 3.0, 3.0 * j - 3.0, 10.0 + 0.5 * i * j;
  return v;
}

int UvIndexOf(int vertex) { return kVertices - 1 - vertex; }
Eigen::Vector2f UvOf(int vertex) {
  return Eigen::Vector2f(static_cast<float>(vertex % kColumns) / (kColumns - 1),
                         static_cast<float>(vertex / kColumns) / (kRows - 1));
}

// Quad q as (v00, v10, v11, v01), counter-clockwise seen from +z.
Eigen::Vector4i Quad(int q) {
  const int i = q % (kColumns - 1), j = q / (kColumns - 1);
  const int v00 = j * kColumns + i;
  return Eigen::Vector4i(v00, v00 + 1, v00 + kColumns + 1, v00 + kColumns);
}

// Identity k: the neutral plus a smooth, distinct displacement (centimetres).
Eigen::Matrix3Xd IdentityDeltaCm(int k) {
  Eigen::Matrix3Xd d(3, kVertices);
  for (int v = 0; v < kVertices; ++v)
    for (int r = 0; r < 3; ++r) d(r, v) = 0.4 * std::sin(1.3 * v + 2.1 * r + 0.7 * k + 0.2);
  return d;
}

Eigen::Matrix3Xd ExpressionDeltaCm(int e) {
  Eigen::Matrix3Xd d = Eigen::Matrix3Xd::Zero(3, kVertices);
  if (e == 0)  // jawOpen: the bottom row drops 1.5 cm
    for (int i = 0; i < kColumns; ++i) d(1, i) = -1.5;
  if (e == 1) d(2, 5) = -0.3;  // eyeBlink_L
  if (e == 2)
    for (int v = 0; v < kVertices; ++v) d.col(v) << 0.2 * std::cos(v), 0.1 * v / kVertices, -0.05;
  // e == 3 (cheekPuff_L): identical to the neutral.
  return d;
}

std::string ObjText(const Eigen::Matrix3Xd& v) {
  std::string text = "# synthetic test mesh\nmtllib none.mtl\n";
  char line[160];
  for (int i = 0; i < v.cols(); ++i) {
    std::snprintf(line, sizeof(line), "v %.12g %.12g %.12g\n", v(0, i), v(1, i), v(2, i));
    text += line;
  }
  for (int k = 0; k < kVertices; ++k) {
    const Eigen::Vector2f uv = UvOf(kVertices - 1 - k);
    std::snprintf(line, sizeof(line), "vt %.9g %.9g\n", uv.x(), uv.y());
    text += line;
  }
  text += "g face\n";
  for (int q = 0; q < kQuads; ++q) {
    text += "f";
    for (int c = 0; c < 4; ++c) {
      const int v = Quad(q)[c];
      text += " " + std::to_string(v + 1) + "/" + std::to_string(UvIndexOf(v) + 1);
    }
    text += "\n";
  }
  return text;
}

std::vector<int> Landmarks() {
  std::vector<int> landmarks;
  for (int i = 0; i < 68; ++i) landmarks.push_back((i * 5) % kVertices);
  return landmarks;
}
const std::vector<int> kRigidLandmarks = {0, 36, 39, 42, 45, 16, 28, 31, 35};
const std::vector<int> kRigidVertices = {0, 1, 2};
const std::vector<int> kFittingVertices = {3, 4, 5, 6, 11};

std::string JsonList(const std::vector<int>& values) {
  std::string text = "[";
  for (size_t i = 0; i < values.size(); ++i) text += (i ? ", " : "") + std::to_string(values[i]);
  return text + "]";
}

std::string IndicesJson() {
  std::string names;
  for (size_t e = 0; e < kExpressions.size(); ++e) names += (e ? ", \"" : "\"") + kExpressions[e] + "\"";
  return "{\n  \"expressions\": [" + names + "],\n  \"fitting_expressions\": [" + names +
         "],\n  \"incompatibilities\": [],\n  \"idx_to_fitting_verts\": " + JsonList(kFittingVertices) +
         ",\n  \"idx_to_rigid_verts\": " + JsonList(kRigidVertices) + ",\n  \"idx_to_lap_rigid_verts\": [1, 2]" +
         ",\n  \"idx_to_landmark_verts\": " + JsonList(Landmarks()) +
         ",\n  \"idx_to_rigid_landmark_idx\": " + JsonList(kRigidLandmarks) + "\n}\n";
}

// `identities`: each identity shape's displacement from the neutral
// (centimetres); empty: kIdentities of IdentityDeltaCm.
void WriteSyntheticIct(const fs::path& dir, std::vector<Eigen::Matrix3Xd> identities = {}) {
  fs::create_directories(dir);
  const Eigen::Matrix3Xd neutral = NeutralCm();
  WriteText(dir / "generic_neutral_mesh.obj", ObjText(neutral));
  if (identities.empty())
    for (int k = 0; k < kIdentities; ++k) identities.push_back(IdentityDeltaCm(k));
  for (size_t k = 0; k < identities.size(); ++k) {
    char name[48];
    std::snprintf(name, sizeof(name), "identity%03zu.obj", k);
    WriteText(dir / name, ObjText(neutral + identities[k]));
  }
  for (size_t e = 0; e < kExpressions.size(); ++e)
    WriteText(dir / (kExpressions[e] + ".obj"), ObjText(neutral + ExpressionDeltaCm(static_cast<int>(e))));
  WriteText(dir / "vertex_indices.json", IndicesJson());
  WriteText(dir / "ICTFaceModelMaterial.mtl", "newmtl none\n");
}

// Float storage of coordinates near 0.1 m is exact to ~10 nm; 1 um leaves
// room for the basis/variance round trip.
constexpr float kToleranceM = 1e-6f;

TEST(ImportIctFaceKit, SyntheticFolderRoundTripsThroughTheLoader) {
  const fs::path dir = ScratchDir();
  WriteSyntheticIct(dir / "FaceXModel");
  const fs::path out = dir / "model" / "ict.h5";
  IctImportSummary summary;
  const Status status = ImportIctFaceKit((dir / "FaceXModel").string(), out.string(), IctImportOptions(), &summary);
  ASSERT_TRUE(status.ok()) << status.message();
  EXPECT_EQ(summary.num_vertices, kVertices);
  EXPECT_EQ(summary.num_polygons, kQuads);
  EXPECT_EQ(summary.num_triangles, 2 * kQuads);
  EXPECT_EQ(summary.num_uvs, kVertices);
  EXPECT_EQ(summary.num_identities, kIdentities);
  EXPECT_EQ(summary.num_expressions, static_cast<int>(kExpressions.size()));
  EXPECT_EQ(summary.num_landmarks, 68);
  EXPECT_EQ(summary.num_regions, 0);  // not the released ICT topology
  EXPECT_FALSE(fs::exists(out.string() + ".partial"));

  FaceModel model;
  const Status loaded = FaceModel::Load(out.string(), &model);
  ASSERT_TRUE(loaded.ok()) << loaded.message();
  ASSERT_EQ(model.num_vertices(), kVertices);
  ASSERT_EQ(model.num_triangles(), 2 * kQuads);
  ASSERT_EQ(model.num_identity(), kIdentities);
  ASSERT_EQ(model.num_expressions(), static_cast<int>(kExpressions.size()));
  EXPECT_EQ(model.expression_names(), kExpressions);

  // The neutral is the OBJ in metres, and the mean shape.
  const Eigen::Matrix3Xd neutral_m = 0.01 * NeutralCm();
  EXPECT_LT((model.neutral().cast<double>() - neutral_m).cwiseAbs().maxCoeff(), kToleranceM);
  EXPECT_LT((model.Vertices(Eigen::VectorXf(), Eigen::VectorXf()).cast<double>() - neutral_m).cwiseAbs().maxCoeff(),
            kToleranceM);

  // Quads split as fans from their first corner: (a, b, c), (a, c, d).
  for (int q = 0; q < kQuads; ++q) {
    const Eigen::Vector4i c = Quad(q);
    EXPECT_EQ(model.triangles().col(2 * q), Eigen::Vector3i(c[0], c[1], c[2])) << "quad " << q;
    EXPECT_EQ(model.triangles().col(2 * q + 1), Eigen::Vector3i(c[0], c[2], c[3])) << "quad " << q;
  }

  // alpha = unit vector k reproduces identityK.obj: one standard deviation.
  for (int k = 0; k < kIdentities; ++k) {
    const Eigen::VectorXf alpha = Eigen::VectorXf::Unit(kIdentities, k);
    const Eigen::Matrix3Xd expected = 0.01 * (NeutralCm() + IdentityDeltaCm(k));
    EXPECT_LT((model.Vertices(alpha, Eigen::VectorXf()).cast<double>() - expected).cwiseAbs().maxCoeff(), kToleranceM)
        << "identity " << k;
  }
  // ... and the model is linear in alpha, as the toolkit's sum of deltas.
  const Eigen::Vector3f alpha(0.5f, -1.2f, 2.0f);
  Eigen::Matrix3Xd combined = NeutralCm();
  for (int k = 0; k < kIdentities; ++k) combined += alpha[k] * IdentityDeltaCm(k);
  EXPECT_LT((model.Vertices(alpha, Eigen::VectorXf()).cast<double>() - 0.01 * combined).cwiseAbs().maxCoeff(),
            kToleranceM);

  // beta = unit vector e reproduces the expression's OBJ, also on top of an identity.
  for (size_t e = 0; e < kExpressions.size(); ++e) {
    const Eigen::VectorXf beta = Eigen::VectorXf::Unit(kExpressions.size(), e);
    const Eigen::Matrix3Xd expected = 0.01 * (NeutralCm() + ExpressionDeltaCm(static_cast<int>(e)));
    EXPECT_LT((model.Vertices(Eigen::VectorXf(), beta).cast<double>() - expected).cwiseAbs().maxCoeff(), kToleranceM)
        << kExpressions[e];
  }
  const Eigen::Matrix3Xd both = 0.01 * (NeutralCm() + IdentityDeltaCm(1) + ExpressionDeltaCm(0));
  EXPECT_LT((model.Vertices(Eigen::VectorXf::Unit(kIdentities, 1), Eigen::VectorXf::Unit(4, 0)).cast<double>() - both)
                .cwiseAbs()
                .maxCoeff(),
            kToleranceM);

  // Per-corner UVs follow the same split.
  ASSERT_TRUE(model.has_uv());
  ASSERT_EQ(model.uv_coords().cols(), kVertices);
  ASSERT_EQ(model.uv_triangles().cols(), model.num_triangles());
  for (int t = 0; t < model.num_triangles(); ++t)
    for (int k = 0; k < 3; ++k) {
      const int v = model.triangles()(k, t);
      EXPECT_EQ(model.uv_triangles()(k, t), UvIndexOf(v));
      EXPECT_LT((model.uv_coords().col(model.uv_triangles()(k, t)) - UvOf(v)).norm(), 1e-7f);
    }

  EXPECT_EQ(model.landmarks_ibug68(), Landmarks());
  EXPECT_EQ(model.rigid_landmarks(), kRigidLandmarks);
  EXPECT_EQ(model.rigid_vertices(), kRigidVertices);
  EXPECT_EQ(model.fitting_vertices(), kFittingVertices);
  EXPECT_TRUE(model.regions().empty());
}

TEST(ImportIctFaceKit, WritesTheBaselPcaConvention) {
  const fs::path dir = ScratchDir();
  WriteSyntheticIct(dir);
  const fs::path out = dir / "ict.h5";
  ASSERT_TRUE(ImportIctFaceKit(dir.string(), out.string(), IctImportOptions()).ok());
  // pcaBasis holds unit columns and pcaVariance the squared length of each
  // shape's difference to the neutral, in square metres; a zero difference
  // (cheekPuff_L here) gives a zero column and zero variance.
  H5::H5File file(out.string(), H5F_ACC_RDONLY);
  auto read = [&](const std::string& path, size_t size) {
    std::vector<float> values(size);
    file.openDataSet(path).read(values.data(), H5::PredType::NATIVE_FLOAT);
    return values;
  };
  const size_t n3 = 3 * kVertices;
  const auto variance = read("/shape/model/pcaVariance", kIdentities);
  const auto basis = read("/shape/model/pcaBasis", n3 * kIdentities);
  for (int k = 0; k < kIdentities; ++k) {
    const double expected = (0.01 * IdentityDeltaCm(k)).squaredNorm();
    EXPECT_NEAR(variance[k], expected, 1e-6 * expected) << "identity " << k;
    double squared = 0;
    for (size_t r = 0; r < n3; ++r) squared += basis[r * kIdentities + k] * basis[r * kIdentities + k];
    EXPECT_NEAR(squared, 1.0, 1e-5) << "identity " << k;
  }
  const size_t e_count = kExpressions.size();
  const auto expression_variance = read("/expression/model/pcaVariance", e_count);
  const auto expression_mean = read("/expression/model/mean", n3);
  EXPECT_NEAR(expression_variance[0], (0.01 * ExpressionDeltaCm(0)).squaredNorm(), 1e-9);
  EXPECT_EQ(expression_variance[3], 0.0f);
  for (float m : expression_mean) EXPECT_EQ(m, 0.0f);
}

TEST(ImportIctFaceKit, WithoutAnExpressionListEveryOtherObjIsABlendshape) {
  const fs::path dir = ScratchDir();
  WriteSyntheticIct(dir);
  WriteText(dir / "vertex_indices.json", "{\"idx_to_rigid_verts\": [1]}");
  const fs::path out = dir / "ict.h5";
  IctImportOptions options;
  options.max_identities = 2;
  const Status status = ImportIctFaceKit(dir.string(), out.string(), options);
  ASSERT_TRUE(status.ok()) << status.message();
  FaceModel model;
  ASSERT_TRUE(FaceModel::Load(out.string(), &model).ok());
  EXPECT_EQ(model.num_identity(), 2);
  const std::vector<std::string> sorted = {"cheekPuff_L", "eyeBlink_L", "jawOpen", "mouthSmile_R"};
  EXPECT_EQ(model.expression_names(), sorted);
  EXPECT_TRUE(model.landmarks_ibug68().empty());
}

// Each bad folder gives its own error, names the culprit, and writes nothing.
class ImportIctFaceKitErrors : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = ScratchDir();
    WriteSyntheticIct(dir_);
    out_ = dir_ / "out" / "ict.h5";
  }
  Status Import() { return ImportIctFaceKit(dir_.string(), out_.string(), IctImportOptions()); }
  void ExpectError(Status::Code code, const std::string& mentions) {
    const Status status = Import();
    EXPECT_EQ(status.code(), code) << status.message();
    EXPECT_NE(status.message().find(mentions), std::string::npos) << status.message();
    EXPECT_FALSE(fs::exists(out_));
    EXPECT_FALSE(fs::exists(out_.string() + ".partial"));
  }
  fs::path dir_, out_;
};

TEST_F(ImportIctFaceKitErrors, MissingFolder) {
  const Status status = ImportIctFaceKit((dir_ / "nowhere").string(), out_.string(), IctImportOptions());
  EXPECT_EQ(status.code(), Status::Code::kNotFound);
  EXPECT_NE(status.message().find("nowhere"), std::string::npos) << status.message();
  const Status file = ImportIctFaceKit((dir_ / "jawOpen.obj").string(), out_.string(), IctImportOptions());
  EXPECT_EQ(file.code(), Status::Code::kInvalidArgument) << file.message();
}

TEST_F(ImportIctFaceKitErrors, MissingNeutralMesh) {
  fs::remove(dir_ / "generic_neutral_mesh.obj");
  ExpectError(Status::Code::kNotFound, "generic_neutral_mesh.obj");
}

TEST_F(ImportIctFaceKitErrors, MissingIndexFile) {
  fs::remove(dir_ / "vertex_indices.json");
  ExpectError(Status::Code::kNotFound, "vertex_indices.json");
}

TEST_F(ImportIctFaceKitErrors, IdentityWithAnotherVertexCount) {
  WriteText(dir_ / "identity001.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  ExpectError(Status::Code::kDataError, "identity001.obj has 3 vertices");
}

TEST_F(ImportIctFaceKitErrors, ExpressionWithAnotherVertexCount) {
  WriteText(dir_ / "eyeBlink_L.obj", ObjText(NeutralCm().leftCols(kVertices - 1)));
  ExpectError(Status::Code::kDataError, "eyeBlink_L.obj has 11 vertices");
}

TEST_F(ImportIctFaceKitErrors, MalformedJson) {
  WriteText(dir_ / "vertex_indices.json", "{\"expressions\": [\"jawOpen\",");
  ExpectError(Status::Code::kDataError, "vertex_indices.json");
}

TEST_F(ImportIctFaceKitErrors, JsonOfTheWrongShape) {
  WriteText(dir_ / "vertex_indices.json", "{\"expressions\": 5}");
  ExpectError(Status::Code::kDataError, "\"expressions\"");
  WriteText(dir_ / "vertex_indices.json", "{\"idx_to_landmark_verts\": [1, \"two\"]}");
  ExpectError(Status::Code::kDataError, "idx_to_landmark_verts");
  WriteText(dir_ / "vertex_indices.json", "[1, 2, 3]");
  ExpectError(Status::Code::kDataError, "JSON object");
}

TEST_F(ImportIctFaceKitErrors, IndexBeyondTheMesh) {
  WriteText(dir_ / "vertex_indices.json", "{\"idx_to_fitting_verts\": [0, 12]}");
  ExpectError(Status::Code::kDataError, "vertex index 12");
  WriteText(dir_ / "vertex_indices.json", "{\"idx_to_landmark_verts\": [1, 2, 3]}");
  ExpectError(Status::Code::kDataError, "68");
}

TEST_F(ImportIctFaceKitErrors, ListedExpressionMissing) {
  fs::remove(dir_ / "mouthSmile_R.obj");
  ExpectError(Status::Code::kNotFound, "mouthSmile_R.obj");
}

TEST_F(ImportIctFaceKitErrors, GapInTheIdentityNumbers) {
  fs::remove(dir_ / "identity001.obj");
  ExpectError(Status::Code::kDataError, "identity001.obj is missing");
}

TEST_F(ImportIctFaceKitErrors, NoIdentityShapes) {
  for (int k = 0; k < kIdentities; ++k) {
    char name[32];
    std::snprintf(name, sizeof(name), "identity%03d.obj", k);
    fs::remove(dir_ / name);
  }
  ExpectError(Status::Code::kNotFound, "identity000.obj");
}

TEST_F(ImportIctFaceKitErrors, MalformedObjNamesTheLine) {
  std::string text = ObjText(NeutralCm());
  text.replace(text.find("v "), 2, "v 1 2\nv ");  // a vertex with two coordinates on line 3
  WriteText(dir_ / "generic_neutral_mesh.obj", text);
  ExpectError(Status::Code::kDataError, "generic_neutral_mesh.obj:3:");
  WriteText(dir_ / "generic_neutral_mesh.obj", ObjText(NeutralCm()) + "f 1 2 99\n");
  ExpectError(Status::Code::kDataError, "vertex 99");
  WriteText(dir_ / "generic_neutral_mesh.obj", ObjText(NeutralCm()) + "f 1/1 2\n");
  ExpectError(Status::Code::kDataError, "three corners");
}

TEST_F(ImportIctFaceKitErrors, BadOptions) {
  IctImportOptions options;
  options.scale = 0;
  EXPECT_EQ(ImportIctFaceKit(dir_.string(), out_.string(), options).code(), Status::Code::kInvalidArgument);
  options.scale = 0.01;
  options.max_identities = -1;
  EXPECT_EQ(ImportIctFaceKit(dir_.string(), out_.string(), options).code(), Status::Code::kInvalidArgument);
  EXPECT_EQ(ImportIctFaceKit(dir_.string(), "", IctImportOptions()).code(), Status::Code::kInvalidArgument);
}

TEST_F(ImportIctFaceKitErrors, FailureKeepsAnEarlierFile) {
  ASSERT_TRUE(Import().ok());
  const auto size = fs::file_size(out_);
  fs::remove(dir_ / "jawOpen.obj");
  EXPECT_EQ(Import().code(), Status::Code::kNotFound);
  ASSERT_TRUE(fs::exists(out_));
  EXPECT_EQ(fs::file_size(out_), size);
  FaceModel model;
  EXPECT_TRUE(FaceModel::Load(out_.string(), &model).ok());
}

// A model whose identity shapes are the neutral pitched by 2 degrees (to first
// order, as the function measures) and moved 3 mm along y: its modes imitate those two motions completely and a yaw only
// in part. Points: the whole grid (its centroid is the pivot, as in the function).
TEST(RigidImitation, ModesThatAreRigidMotionsImitateThem) {
  const fs::path dir = ScratchDir();
  const Eigen::Matrix3Xd neutral = NeutralCm();
  const Eigen::Vector3d centre = neutral.rowwise().mean();
  Eigen::Matrix3Xd pitched(3, kVertices), moved = Eigen::Matrix3Xd::Zero(3, kVertices);
  for (int v = 0; v < kVertices; ++v) {
    pitched.col(v) = (2.0 * M_PI / 180.0) * Eigen::Vector3d::UnitX().cross(neutral.col(v) - centre);
    moved(1, v) = 0.3;
  }
  WriteSyntheticIct(dir / "ict", {pitched, moved});
  ASSERT_TRUE(ImportIctFaceKit((dir / "ict").string(), (dir / "model.h5").string(), IctImportOptions()).ok());
  FaceModel model;
  ASSERT_TRUE(FaceModel::Load((dir / "model.h5").string(), &model).ok());
  std::vector<RigidImitation> rows;
  ASSERT_TRUE(ImitateRigidMotions(model, 2, "all", &rows).ok());
  ASSERT_EQ(rows.size(), 7u);
  // Float storage of the model leaves about 1e-6 of the motion over.
  EXPECT_NEAR(rows[0].shared, 1.0, 1e-5) << rows[0].motion;
  EXPECT_LT(rows[0].left_over_mm, 1e-4 * rows[0].motion_mm);
  EXPECT_NEAR(rows[4].shared, 1.0, 1e-5) << rows[4].motion;
  EXPECT_LT(rows[4].left_over_mm, 1e-4 * rows[4].motion_mm);
  EXPECT_GT(rows[4].alpha_norm, 0.0);
  for (int m : {1, 2, 3, 5}) EXPECT_LT(rows[m].shared, 0.9) << rows[m].motion;
  // Shared and left over split the motion's displacement: shared^2 + (left/motion)^2 = 1.
  for (const auto& r : rows)
    EXPECT_NEAR(r.shared * r.shared + std::pow(r.left_over_mm / r.motion_mm, 2), 1.0, 1e-9) << r.motion;
  // Bad requests are refused.
  EXPECT_FALSE(ImitateRigidMotions(model, 3, "all", &rows).ok());
  EXPECT_FALSE(ImitateRigidMotions(model, 0, "all", &rows).ok());
  EXPECT_FALSE(ImitateRigidMotions(model, 2, "no such region", &rows).ok());
}

}  // namespace
}  // namespace headforge
