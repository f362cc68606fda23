// The shipped landmark data measured again where it is cheap enough for
// the suite but not for the fast tier: renders of new subjects through the
// detector (integration).
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <random>
#include <stdexcept>

#include "calibration/landmark_embedding.h"
#include "core/face_model.h"
#include "core/paths.h"
#include "reconstruction/landmark_basis.h"

namespace headforge {
namespace {

const FaceModel& Model() {
  static const FaceModel* model = [] {
    auto* m = new FaceModel();
    const Status s = FaceModel::Load(std::string(HEADFORGE_TEST_SHARED_DATA) + "/ict_facekit/ict_face_model.h5", m);
    if (!s.ok()) throw std::runtime_error(s.message());
    return m;
  }();
  return *model;
}

// The shipped identity columns (data/ict_dlib68_landmark_embedding_identity.json,
// `headforge embed-landmarks --identity`) against subjects they were not
// fitted to: three new faces, skins and lights, measured by the detector on
// renders, are predicted closer than by the plain points riding on the surface.
TEST(IdentityLandmarks, ShippedColumnsPredictNewSubjects) {
  LandmarkEmbedding shipped;
  ASSERT_TRUE(ReadLandmarkEmbedding(IdentityLandmarkEmbedding(), &shipped).ok());
  ASSERT_EQ(shipped.identity.size(), 68u);
  const int modes = int(shipped.identity[0].cols());
  LandmarkBasis plain;
  ASSERT_TRUE(BuildLandmarkBasis(Model(), DetectorLandmarkPoints(Model(), DefaultLandmarkEmbedding()), modes, &plain).ok());
  FaceDetectorOptions detector;
  detector.ultraface_dir = std::string(HEADFORGE_TEST_SHARED_DATA) + "/models/ultraface";
  std::vector<double> with_columns, riding;
  for (int s = 0; s < 3; ++s) {
    std::mt19937_64 rng(5000 + s);
    std::normal_distribution<double> normal;
    SubjectLook look;
    look.alpha = Eigen::VectorXd::NullaryExpr(modes, [&] { return normal(rng); });
    look.skin = s == 1 ? Eigen::Vector3d(0.50, 0.34, 0.25) : Eigen::Vector3d(0.82, 0.63, 0.52);
    look.light = Eigen::Vector3d(-0.3 + 0.3 * s, 0.4, 0.9);
    std::vector<Eigen::Vector3d> points;
    std::vector<int> seen;
    ASSERT_TRUE(MeasureSubjectLandmarks(Model(), detector, DefaultLandmarkModel(), 2, look, &points, &seen).ok());
    for (int i = 0; i < 68; ++i) {
      if (seen[i] < 10) continue;
      with_columns.push_back((shipped.points[i] + shipped.identity[i] * look.alpha - points[i]).norm());
      riding.push_back((plain.Point(i, look.alpha, Eigen::VectorXd()) - points[i]).norm());
    }
  }
  ASSERT_GT(with_columns.size(), 150u);
  std::sort(with_columns.begin(), with_columns.end());
  std::sort(riding.begin(), riding.end());
  const double a = with_columns[with_columns.size() / 2], b = riding[riding.size() / 2];
  std::printf("new subjects' detector points: %.2f mm from the identity columns' prediction, %.2f mm from the plain "
              "points on the surface (medians)\n", 1e3 * a, 1e3 * b);
  EXPECT_LT(a, 0.8 * b);
}

}  // namespace
}  // namespace headforge
