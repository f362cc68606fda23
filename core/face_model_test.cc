#include "core/face_model.h"

#include <gtest/gtest.h>

#include "core/fs.h"

namespace headforge {
namespace {

const std::string kModel =
    (fs::path(HEADFORGE_TEST_SHARED_DATA) / "ict_facekit" / "ict_face_model.h5").string();

class FaceModelTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    model_ = new FaceModel();
    const Status status = FaceModel::Load(kModel, model_);
    ASSERT_TRUE(status.ok()) << status.message();
  }
  static void TearDownTestSuite() { delete model_; }
  static FaceModel* model_;
};
FaceModel* FaceModelTest::model_ = nullptr;

TEST_F(FaceModelTest, LoadsTheIctLayout) {
  EXPECT_EQ(model_->num_vertices(), 26719);
  EXPECT_EQ(model_->num_triangles(), 52220);
  EXPECT_EQ(model_->num_identity(), 100);
  EXPECT_EQ(model_->num_expressions(), 53);
  EXPECT_EQ(model_->landmarks_ibug68().size(), 68u);
  EXPECT_EQ(model_->rigid_landmarks().size(), 9u);
  EXPECT_TRUE(model_->has_uv());
  EXPECT_EQ(model_->uv_coords().cols(), 28911);
  EXPECT_GE(model_->ExpressionIndex("jawOpen"), 0);
  EXPECT_GE(model_->ExpressionIndex("eyeBlink_L"), 0);
  EXPECT_EQ(model_->ExpressionIndex("noSuchShape"), -1);
  ASSERT_NE(model_->FindRegion("face"), nullptr);
  EXPECT_EQ(model_->FindRegion("face")->first_vertex, 0);
}

TEST_F(FaceModelTest, NeutralShapeIsTheMeanAndInTheHeadFrame) {
  const Eigen::Matrix3Xf v = model_->Vertices(Eigen::VectorXf(), Eigen::VectorXf());
  EXPECT_LT((v - model_->neutral()).cwiseAbs().maxCoeff(), 1e-5f);
  // The nose tip (iBUG 30) is at z ~ 0.13 m, on the symmetry plane, and the
  // face looks toward +z: the nose is in front of the eye corners.
  const Eigen::Vector3f nose = v.col(model_->landmarks_ibug68()[30]);
  const Eigen::Vector3f eye = v.col(model_->landmarks_ibug68()[36]);
  EXPECT_NEAR(nose.z(), 0.13f, 0.02f);
  EXPECT_NEAR(nose.x(), 0.0f, 0.005f);
  EXPECT_GT(nose.z(), eye.z());
  // +y up: the eyes are above the chin (iBUG 8).
  EXPECT_GT(eye.y(), v.col(model_->landmarks_ibug68()[8]).y());
  // The subject's right eye (iBUG 36) is on -x in a right-handed frame facing +z.
  EXPECT_LT(eye.x(), 0.0f);
}

TEST_F(FaceModelTest, JawOpenMovesTheChinDown) {
  Eigen::VectorXf beta = Eigen::VectorXf::Zero(model_->num_expressions());
  beta[model_->ExpressionIndex("jawOpen")] = 1.0f;
  const Eigen::Matrix3Xf open = model_->Vertices(Eigen::VectorXf(), beta);
  const int chin = model_->landmarks_ibug68()[8];
  EXPECT_LT(open(1, chin), model_->neutral()(1, chin) - 0.01f);
}

TEST_F(FaceModelTest, IdentityIsLinearInAlpha) {
  Eigen::VectorXf a = Eigen::VectorXf::Zero(10), b = Eigen::VectorXf::Zero(10);
  a[0] = 1.0f;
  b[3] = -2.0f;
  const Eigen::Matrix3Xf mean = model_->Identity(Eigen::VectorXf());
  const Eigen::Matrix3Xf sum = model_->Identity(a + b) - mean;
  const Eigen::Matrix3Xf parts = (model_->Identity(a) - mean) + (model_->Identity(b) - mean);
  EXPECT_LT((sum - parts).cwiseAbs().maxCoeff(), 1e-5f);
  // One standard deviation moves vertices by millimetres, not metres.
  const float step = (model_->Identity(a) - mean).colwise().norm().maxCoeff();
  EXPECT_GT(step, 1e-4f);
  EXPECT_LT(step, 0.05f);
}

TEST(FaceModel, BadFilesAreReported) {
  FaceModel model;
  EXPECT_EQ(FaceModel::Load("/no/model.h5", &model).code(), Status::Code::kNotFound);
  const fs::path bad = fs::temp_directory_path() / "hf_not_hdf5.h5";
  ASSERT_TRUE(WriteFileAtomic(bad, "plain text").ok());
  const Status status = FaceModel::Load(bad.string(), &model);
  EXPECT_EQ(status.code(), Status::Code::kDataError);
  EXPECT_NE(status.message().find("not an HDF5 file"), std::string::npos);
}

}  // namespace
}  // namespace headforge
