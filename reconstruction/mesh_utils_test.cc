#include "reconstruction/mesh_utils.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <map>
#include <utility>
#include <vector>

#include "core/face_model.h"
#include "core/fs.h"

namespace headforge {
namespace {

struct TestMesh {
  Eigen::Matrix3Xf vertices;
  Eigen::Matrix3Xi triangles;
};

// A unit icosahedron, each triangle split in four `subdivisions` times with
// the new vertices pushed onto the unit sphere; counter-clockwise seen from
// outside.
TestMesh UnitIcosphere(int subdivisions) {
  const double g = (1.0 + std::sqrt(5.0)) / 2.0;
  std::vector<Eigen::Vector3d> points = {{-1, g, 0}, {1, g, 0}, {-1, -g, 0}, {1, -g, 0}, {0, -1, g}, {0, 1, g},
                                         {0, -1, -g}, {0, 1, -g}, {g, 0, -1}, {g, 0, 1}, {-g, 0, -1}, {-g, 0, 1}};
  for (auto& p : points) p.normalize();
  std::vector<Eigen::Vector3i> faces = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                                        {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                                        {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                                        {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
  for (int s = 0; s < subdivisions; ++s) {
    std::map<std::pair<int, int>, int> midpoints;
    auto midpoint = [&](int a, int b) {
      const std::pair<int, int> key = std::minmax(a, b);
      const auto found = midpoints.find(key);
      if (found != midpoints.end()) return found->second;
      points.push_back((points[a] + points[b]).normalized());
      return midpoints[key] = static_cast<int>(points.size()) - 1;
    };
    std::vector<Eigen::Vector3i> finer;
    for (const auto& f : faces) {
      const int ab = midpoint(f[0], f[1]), bc = midpoint(f[1], f[2]), ca = midpoint(f[2], f[0]);
      finer.push_back({f[0], ab, ca});
      finer.push_back({f[1], bc, ab});
      finer.push_back({f[2], ca, bc});
      finer.push_back({ab, bc, ca});
    }
    faces = finer;
  }
  TestMesh mesh;
  mesh.vertices.resize(3, points.size());
  for (size_t i = 0; i < points.size(); ++i) mesh.vertices.col(i) = points[i].cast<float>();
  mesh.triangles.resize(3, faces.size());
  for (size_t t = 0; t < faces.size(); ++t) mesh.triangles.col(t) = faces[t];
  return mesh;
}

SurfaceSamples OneSample(int triangle, float w0, float w1, float w2) {
  SurfaceSamples samples;
  samples.triangles = Eigen::VectorXi::Constant(1, triangle);
  samples.barycentric.resize(3, 1);
  samples.barycentric << w0, w1, w2;
  return samples;
}

double AngleDegrees(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::atan2(a.cross(b).norm(), a.dot(b)) * 180.0 / std::acos(-1.0);
}

// The largest angle, in degrees, between each vertex normal and the sphere's
// analytic (radial) normal; also checks that every normal is unit and outward.
double WorstAngleToRadius(const TestMesh& mesh, const Eigen::Matrix3Xf& normals) {
  double worst = 0;
  for (int i = 0; i < normals.cols(); ++i) {
    const Eigen::Vector3d n = normals.col(i).cast<double>();
    const Eigen::Vector3d radial = mesh.vertices.col(i).cast<double>().normalized();
    EXPECT_NEAR(n.norm(), 1.0, 1e-6);
    EXPECT_GT(n.dot(radial), 0.0) << "vertex " << i << " points inward";
    worst = std::max(worst, AngleDegrees(n, radial));
  }
  return worst;
}

TEST(VertexNormals, ClosedIcosphereNormalsPointOutwardAlongTheRadius) {
  TestMesh mesh = UnitIcosphere(3);  // 642 vertices, 1280 triangles
  mesh.vertices *= 0.1f;             // a head-sized sphere, 10 cm radius
  // The construction is counter-clockwise from outside: every face normal points away from the centre.
  Eigen::Matrix3Xd direct = Eigen::Matrix3Xd::Zero(3, mesh.vertices.cols());
  for (int t = 0; t < mesh.triangles.cols(); ++t) {
    const Eigen::Vector3d a = mesh.vertices.col(mesh.triangles(0, t)).cast<double>(),
                          b = mesh.vertices.col(mesh.triangles(1, t)).cast<double>(),
                          c = mesh.vertices.col(mesh.triangles(2, t)).cast<double>();
    const Eigen::Vector3d twice_area_normal = (b - a).cross(c - a);
    ASSERT_GT(twice_area_normal.dot(a + b + c), 0.0);
    for (int k = 0; k < 3; ++k) direct.col(mesh.triangles(k, t)) += twice_area_normal;
  }
  Eigen::Matrix3Xf normals;
  const Status status = ComputeVertexNormals(mesh.vertices, mesh.triangles, &normals);
  ASSERT_TRUE(status.ok()) << status.message();
  ASSERT_EQ(normals.cols(), mesh.vertices.cols());
  // Area weighting: the normal is the direction of the summed face cross products.
  EXPECT_LT((normals.cast<double>() - direct.colwise().normalized()).cwiseAbs().maxCoeff(), 1e-6);
  // The analytic normal is radial. The discrete one deviates where the
  // tessellation around a vertex is not symmetric: 0.68 degrees at most here,
  // halving with each subdivision (first order in the edge length).
  const double worst = WorstAngleToRadius(mesh, normals);
  EXPECT_LT(worst, 1.0) << "worst angle to the radial direction, degrees";
  const TestMesh finer = UnitIcosphere(4);
  ASSERT_TRUE(ComputeVertexNormals(finer.vertices, finer.triangles, &normals).ok());
  EXPECT_LT(WorstAngleToRadius(finer, normals), 0.6 * worst);
}

TEST(VertexNormals, EllipsoidNormalsMatchTheAnalyticGradient) {
  // A head-like ellipsoid x^2/a^2 + y^2/b^2 + z^2/c^2 = 1: its outward normal
  // at p is the gradient (x/a^2, y/b^2, z/c^2), normalised.
  const TestMesh sphere = UnitIcosphere(4);  // 2562 vertices
  const Eigen::Vector3d radii(0.075, 0.11, 0.095);
  const Eigen::Matrix3Xf vertices = radii.cast<float>().asDiagonal() * sphere.vertices;
  Eigen::Matrix3Xf normals;
  ASSERT_TRUE(ComputeVertexNormals(vertices, sphere.triangles, &normals).ok());
  double worst = 0;
  for (int i = 0; i < normals.cols(); ++i) {
    const Eigen::Vector3d p = vertices.col(i).cast<double>();
    const Eigen::Vector3d analytic = p.cwiseQuotient(radii.cwiseProduct(radii)).normalized();
    EXPECT_GT(normals.col(i).cast<double>().dot(analytic), 0.0);
    worst = std::max(worst, AngleDegrees(normals.col(i).cast<double>(), analytic));
  }
  EXPECT_LT(worst, 1.0) << "worst angle to the analytic normal, degrees";
}

TEST(VertexNormals, TrianglesWeighByArea) {
  // Vertex 0 is shared by a triangle of area 0.5 facing +z and one of area 1.5
  // facing +x: the normal is (1.5, 0, 0.5) normalised.
  Eigen::Matrix3Xf vertices(3, 5);
  vertices << 0, 1, 0, 0, 0,  //
      0, 0, 1, 3, 0,          //
      0, 0, 0, 0, 1;
  Eigen::Matrix3Xi triangles(3, 2);
  triangles << 0, 0,  //
      1, 3,           //
      2, 4;
  // Triangle (0, 3, 4): edges (0, 3, 0) and (0, 0, 1) -> cross (3, 0, 0), area 1.5.
  Eigen::Matrix3Xf normals;
  ASSERT_TRUE(ComputeVertexNormals(vertices, triangles, &normals).ok());
  const Eigen::Vector3f expected = Eigen::Vector3f(1.5f, 0, 0.5f).normalized();
  EXPECT_LT((normals.col(0) - expected).norm(), 1e-6f);
  EXPECT_LT((normals.col(1) - Eigen::Vector3f::UnitZ()).norm(), 1e-6f);
  EXPECT_LT((normals.col(4) - Eigen::Vector3f::UnitX()).norm(), 1e-6f);
}

TEST(VertexNormals, NonManifoldTrianglesStillCount) {
  // Three triangles on one edge (0, 1): OpenMesh cannot join the third to its
  // half-edge structure; it must still contribute to vertices 0 and 1.
  Eigen::Matrix3Xf vertices(3, 6);
  vertices << 0, 1, 0, 0, 0, 0.5f,  //
      0, 0, 1, -1, 0, 0.5f,         //
      0, 0, 0, 0, 1, 0.5f;
  Eigen::Matrix3Xi triangles(3, 3);
  triangles << 0, 1, 0,  //
      1, 0, 1,           //
      2, 3, 4;
  // Unnormalised face normals: (0,0,1), (0,0,1) and (0,-1,0); the isolated vertex 5 gets zero.
  Eigen::Matrix3Xf normals;
  ASSERT_TRUE(ComputeVertexNormals(vertices, triangles, &normals).ok());
  const Eigen::Vector3f expected = Eigen::Vector3f(0, -1, 2).normalized();
  EXPECT_LT((normals.col(0) - expected).norm(), 1e-6f);
  EXPECT_LT((normals.col(1) - expected).norm(), 1e-6f);
  EXPECT_LT((normals.col(4) - Eigen::Vector3f(0, -1, 0)).norm(), 1e-6f);
  EXPECT_EQ(normals.col(5), Eigen::Vector3f::Zero());
}

TEST(VertexNormals, FollowsTheMeshAfterInit) {
  const TestMesh mesh = UnitIcosphere(2);
  HalfEdgeNormals computer;
  ASSERT_TRUE(computer.Init(static_cast<int>(mesh.vertices.cols()), mesh.triangles).ok());
  const Eigen::Matrix3f rotation = Eigen::AngleAxisf(0.7f, Eigen::Vector3f(1, 2, 3).normalized()).toRotationMatrix();
  Eigen::Matrix3Xf normals, moved_normals;
  ASSERT_TRUE(computer.Compute(mesh.vertices, &normals).ok());
  const Eigen::Matrix3Xf moved = (rotation * (0.2f * mesh.vertices)).colwise() + Eigen::Vector3f(0.1f, -0.3f, 2.0f);
  ASSERT_TRUE(computer.Compute(moved, &moved_normals).ok());
  EXPECT_LT((moved_normals - rotation * normals).cwiseAbs().maxCoeff(), 1e-5f);
}

TEST(VertexNormals, BadInputIsReported) {
  const TestMesh mesh = UnitIcosphere(0);
  Eigen::Matrix3Xi bad = mesh.triangles;
  bad(1, 3) = 12;  // one past the last vertex
  Eigen::Matrix3Xf normals;
  EXPECT_EQ(ComputeVertexNormals(mesh.vertices, bad, &normals).code(), Status::Code::kInvalidArgument);
  HalfEdgeNormals computer;
  EXPECT_EQ(computer.Compute(mesh.vertices, &normals).code(), Status::Code::kInvalidArgument);  // no Init()
  ASSERT_TRUE(computer.Init(12, mesh.triangles).ok());
  EXPECT_EQ(computer.Compute(mesh.vertices.leftCols(11), &normals).code(), Status::Code::kInvalidArgument);
}

// Two triangles in the z = 0 plane with areas 0.5 and 1.5 (ratio 1:3).
TestMesh TwoTriangles() {
  TestMesh mesh;
  mesh.vertices.resize(3, 6);
  mesh.vertices << 0, 1, 0, 2, 5, 2,  //
      0, 0, 1, 0, 0, 1,               //
      0, 0, 0, 0, 0, 0;
  mesh.triangles.resize(3, 2);
  mesh.triangles << 0, 3,  //
      1, 4,                //
      2, 5;
  return mesh;
}

TEST(SurfaceSampling, DensityIsUniformOverArea) {
  const TestMesh mesh = TwoTriangles();
  constexpr int kCount = 40000;
  SurfaceSamples samples;
  ASSERT_TRUE(SampleSurface(mesh.vertices, mesh.triangles, kCount, 7, &samples).ok());
  ASSERT_EQ(samples.size(), kCount);
  // Between triangles: expected 1/4 and 3/4 of the samples. Chi-square with
  // 1 degree of freedom must stay below 10.83 (p = 0.001).
  int on_small = 0;
  for (int s = 0; s < kCount; ++s) on_small += samples.triangles[s] == 0;
  const double expected_small = kCount * 0.25, expected_large = kCount * 0.75;
  const double chi2_triangles = std::pow(on_small - expected_small, 2) / expected_small +
                                std::pow(kCount - on_small - expected_large, 2) / expected_large;
  EXPECT_LT(chi2_triangles, 10.83) << on_small << " of " << kCount << " on the small triangle";
  // Within the large triangle: its four midpoint sub-triangles have equal
  // areas. Corner sub-triangle k holds the points with weight k above 1/2.
  // Chi-square with 3 degrees of freedom must stay below 16.27 (p = 0.001).
  int cells[4] = {0, 0, 0, 0};
  for (int s = 0; s < kCount; ++s) {
    if (samples.triangles[s] != 1) continue;
    int cell = 3;
    for (int k = 0; k < 3; ++k)
      if (samples.barycentric(k, s) > 0.5f) cell = k;
    ++cells[cell];
  }
  const double per_cell = (kCount - on_small) / 4.0;
  double chi2_cells = 0;
  for (int c : cells) chi2_cells += std::pow(c - per_cell, 2) / per_cell;
  EXPECT_LT(chi2_cells, 16.27) << cells[0] << " " << cells[1] << " " << cells[2] << " " << cells[3];
}

TEST(SurfaceSampling, BarycentricsLieInsideTheirTriangle) {
  const TestMesh mesh = UnitIcosphere(2);
  SurfaceSamples samples;
  ASSERT_TRUE(SampleSurface(mesh.vertices, mesh.triangles, 5000, 3, &samples).ok());
  for (int s = 0; s < samples.size(); ++s) {
    ASSERT_GE(samples.triangles[s], 0);
    ASSERT_LT(samples.triangles[s], mesh.triangles.cols());
    EXPECT_GE(samples.barycentric.col(s).minCoeff(), 0.0f);
    EXPECT_NEAR(samples.barycentric.col(s).sum(), 1.0f, 1e-6f);
  }
}

TEST(SurfaceSampling, SameSeedSameSamples) {
  const TestMesh mesh = UnitIcosphere(2);
  SurfaceSamples a, b, c;
  ASSERT_TRUE(SampleSurface(mesh.vertices, mesh.triangles, 1000, 42, &a).ok());
  ASSERT_TRUE(SampleSurface(mesh.vertices, mesh.triangles, 1000, 42, &b).ok());
  ASSERT_TRUE(SampleSurface(mesh.vertices, mesh.triangles, 1000, 43, &c).ok());
  EXPECT_EQ(a.triangles, b.triangles);
  EXPECT_EQ(a.barycentric, b.barycentric);
  EXPECT_NE(a.triangles, c.triangles);
}

TEST(SurfaceSampling, ZeroAreaTrianglesAreNeverChosen) {
  TestMesh mesh = TwoTriangles();
  // Insert a degenerate triangle (three collinear points) between the two.
  mesh.triangles.conservativeResize(3, 3);
  mesh.triangles.col(2) = mesh.triangles.col(1);
  mesh.triangles.col(1) << 0, 1, 3;
  SurfaceSamples samples;
  ASSERT_TRUE(SampleSurface(mesh.vertices, mesh.triangles, 20000, 5, &samples).ok());
  for (int s = 0; s < samples.size(); ++s) ASSERT_NE(samples.triangles[s], 1);
}

TEST(SurfaceSampling, PositionsFollowTheDeformedMesh) {
  const TestMesh mesh = UnitIcosphere(2);
  SurfaceSamples samples;
  ASSERT_TRUE(SampleSurface(mesh.vertices, mesh.triangles, 2000, 11, &samples).ok());
  const Eigen::Matrix3Xf on_sphere = SamplePositions(samples, mesh.vertices, mesh.triangles);
  // Each sample lies on its triangle's plane, inside the unit sphere's shell.
  for (int s = 0; s < samples.size(); ++s) {
    EXPECT_LE(on_sphere.col(s).norm(), 1.0f + 1e-6f);
    EXPECT_GT(on_sphere.col(s).norm(), 0.9f);
  }
  // An affine deformation maps barycentric combinations to the same
  // combinations of the moved corners: positions on the deformed mesh equal
  // the deformed positions.
  Eigen::Matrix3f linear;
  linear << 1.2f, 0.3f, -0.1f, 0.0f, 0.8f, 0.2f, 0.1f, -0.4f, 1.5f;
  const Eigen::Vector3f shift(0.05f, -0.02f, 0.3f);
  const Eigen::Matrix3Xf deformed = (linear * mesh.vertices).colwise() + shift;
  const Eigen::Matrix3Xf expected = (linear * on_sphere).colwise() + shift;
  EXPECT_LT((SamplePositions(samples, deformed, mesh.triangles) - expected).cwiseAbs().maxCoeff(), 1e-5f);
  // A sample on a corner is that corner, on any shape.
  const SurfaceSamples corner = OneSample(17, 0, 1, 0);
  EXPECT_EQ(SamplePositions(corner, deformed, mesh.triangles).col(0), deformed.col(mesh.triangles(1, 17)));
}

TEST(SurfaceSampling, BadInputIsReported) {
  const TestMesh mesh = TwoTriangles();
  SurfaceSamples samples;
  EXPECT_EQ(SampleSurface(mesh.vertices, mesh.triangles, -1, 0, &samples).code(), Status::Code::kInvalidArgument);
  Eigen::Matrix3Xi bad = mesh.triangles;
  bad(2, 1) = -1;
  EXPECT_EQ(SampleSurface(mesh.vertices, bad, 10, 0, &samples).code(), Status::Code::kInvalidArgument);
  const Eigen::Matrix3Xf flat = Eigen::Matrix3Xf::Zero(3, 6);
  EXPECT_EQ(SampleSurface(flat, mesh.triangles, 10, 0, &samples).code(), Status::Code::kDataError);
  Eigen::Matrix3Xf broken = mesh.vertices;
  broken(0, 4) = NAN;
  EXPECT_EQ(SampleSurface(broken, mesh.triangles, 10, 0, &samples).code(), Status::Code::kDataError);
  EXPECT_TRUE(SampleSurface(mesh.vertices, mesh.triangles, 0, 0, &samples).ok());
  EXPECT_EQ(samples.size(), 0);
}

class IctSurfaceTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    model_ = new FaceModel();
    const std::string path = (fs::path(HEADFORGE_TEST_SHARED_DATA) / "ict_facekit" / "ict_face_model.h5").string();
    const Status status = FaceModel::Load(path, model_);
    ASSERT_TRUE(status.ok()) << status.message();
    ASSERT_TRUE(model_->has_uv());
  }
  static void TearDownTestSuite() { delete model_; }
  static FaceModel* model_;
};
FaceModel* IctSurfaceTest::model_ = nullptr;

TEST_F(IctSurfaceTest, SampleOnAVertexHasThatVertexUv) {
  // Corners of triangles spread over the whole head, each corner in turn.
  SurfaceSamples samples;
  const int stride = model_->num_triangles() / 50;
  for (int t = 0, s = 0; t < model_->num_triangles(); t += stride) {
    for (int k = 0; k < 3; ++k, ++s) {
      samples.triangles.conservativeResize(s + 1);
      samples.barycentric.conservativeResize(3, s + 1);
      samples.triangles[s] = t;
      samples.barycentric.col(s) = Eigen::Vector3f::Unit(k);
    }
  }
  Eigen::Matrix2Xf uvs;
  ASSERT_TRUE(SampleUVs(samples, model_->uv_coords(), model_->uv_triangles(), &uvs).ok());
  const Eigen::Matrix3Xf positions = SamplePositions(samples, model_->neutral(), model_->triangles());
  for (int s = 0; s < samples.size(); ++s) {
    const int t = samples.triangles[s], k = s % 3;
    EXPECT_EQ(uvs.col(s), model_->uv_coords().col(model_->uv_triangles()(k, t))) << "triangle " << t << " corner " << k;
    EXPECT_EQ(positions.col(s), model_->neutral().col(model_->triangles()(k, t)));
  }
  // Midway along an edge: the mean of the two corners' UVs.
  const SurfaceSamples edge = OneSample(1000, 0.5f, 0.5f, 0.0f);
  ASSERT_TRUE(SampleUVs(edge, model_->uv_coords(), model_->uv_triangles(), &uvs).ok());
  const Eigen::Vector2f mean = 0.5f * (model_->uv_coords().col(model_->uv_triangles()(0, 1000)) +
                                       model_->uv_coords().col(model_->uv_triangles()(1, 1000)));
  EXPECT_LT((uvs.col(0) - mean).norm(), 1e-6f);
}

TEST_F(IctSurfaceTest, SamplesCoverTheHeadAndFollowExpressions) {
  SurfaceSamples samples;
  ASSERT_TRUE(SampleSurface(model_->neutral(), model_->triangles(), 20000, 1, &samples).ok());
  Eigen::Matrix2Xf uvs;
  ASSERT_TRUE(SampleUVs(samples, model_->uv_coords(), model_->uv_triangles(), &uvs).ok());
  // ICT lays its parts out in UV tiles side by side (u up to 7); the face's own part is the unit square.
  const FaceModel::Region* face = model_->FindRegion("face");
  ASSERT_NE(face, nullptr);
  int on_face = 0;
  for (int s = 0; s < samples.size(); ++s) {
    EXPECT_TRUE(uvs.col(s).allFinite());
    EXPECT_GE(uvs.col(s).minCoeff(), 0.0f);
    if (!face->ContainsTriangle(samples.triangles[s])) continue;
    ++on_face;
    EXPECT_LE(uvs.col(s).maxCoeff(), 1.0f);
  }
  EXPECT_GT(on_face, 1000);
  // jawOpen moves the samples on the chin down, and leaves the sample on its triangle.
  Eigen::VectorXf beta = Eigen::VectorXf::Zero(model_->num_expressions());
  beta[model_->ExpressionIndex("jawOpen")] = 1.0f;
  const Eigen::Matrix3Xf open = model_->Vertices(Eigen::VectorXf(), beta);
  const Eigen::Matrix3Xf before = SamplePositions(samples, model_->neutral(), model_->triangles());
  const Eigen::Matrix3Xf after = SamplePositions(samples, open, model_->triangles());
  EXPECT_LT((after - before).row(1).minCoeff(), -0.01f);  // some sample drops by more than 1 cm
  Eigen::Matrix3Xf normals;
  ASSERT_TRUE(ComputeVertexNormals(open, model_->triangles(), &normals).ok());
  // The nose tip's normal points forward (+z): the face looks toward +z.
  EXPECT_GT(normals(2, model_->landmarks_ibug68()[30]), 0.8f);
}

TEST_F(IctSurfaceTest, UvLookupRejectsMismatchedInput) {
  const SurfaceSamples samples = OneSample(model_->num_triangles(), 1, 0, 0);  // one past the last triangle
  Eigen::Matrix2Xf uvs;
  EXPECT_EQ(SampleUVs(samples, model_->uv_coords(), model_->uv_triangles(), &uvs).code(),
            Status::Code::kInvalidArgument);
  EXPECT_EQ(SampleUVs(samples, Eigen::Matrix2Xf(), Eigen::Matrix3Xi(), &uvs).code(), Status::Code::kInvalidArgument);
}

}  // namespace
}  // namespace headforge
