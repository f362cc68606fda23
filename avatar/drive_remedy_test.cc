// Cross-identity driving's remedies: a driver whose neutral sits elsewhere,
// vectors already in the avatar's span, and the clamp to [0, 1].
#include "avatar/drive_remedy.h"

#include <gtest/gtest.h>

#include <random>

namespace headforge {
namespace {

constexpr int kWeights = 6;

// The avatar's training expressions: its rest plus two expression directions.
std::vector<Eigen::VectorXd> AvatarTraining() {
  Eigen::VectorXd rest(kWeights), open(kWeights), smile(kWeights);
  rest << 0.05, 0.10, 0.02, 0.0, 0.08, 0.03;
  open << 0.0, 0.5, 0.1, 0.0, 0.0, 0.2;
  smile << 0.3, 0.0, 0.0, 0.25, 0.1, 0.0;
  std::mt19937 random(3);
  std::uniform_real_distribution<double> amount(0.0, 1.0);
  std::vector<Eigen::VectorXd> frames;
  for (int f = 0; f < 40; ++f) frames.push_back(rest + amount(random) * open + amount(random) * smile);
  return frames;
}

Eigen::VectorXd Mean(const std::vector<Eigen::VectorXd>& frames) {
  Eigen::VectorXd mean = Eigen::VectorXd::Zero(frames.front().size());
  for (const Eigen::VectorXd& f : frames) mean += f;
  return mean / double(frames.size());
}

TEST(DriveRemedy, NamesRoundTrip) {
  for (const char* name : {"none", "relative", "relative+span"}) {
    DriveRemedy remedy = DriveRemedy::kNone;
    ASSERT_TRUE(ParseDriveRemedy(name, &remedy).ok());
    EXPECT_EQ(DriveRemedyName(remedy), name);
  }
  DriveRemedy remedy;
  EXPECT_FALSE(ParseDriveRemedy("span", &remedy).ok());
}

TEST(DriveRemedy, RelativePutsTheDriversNeutralOnTheAvatarsMean) {
  const std::vector<Eigen::VectorXd> avatar = AvatarTraining();
  // The driver rests at a neutral shifted by a constant in half its frames
  // and moves away from it (upward) in the others.
  const Eigen::VectorXd neutral = Eigen::VectorXd::Constant(kWeights, 0.2);
  std::vector<Eigen::VectorXd> driver;
  std::mt19937 random(5);
  std::uniform_real_distribution<double> amount(0.0, 0.3);
  for (int f = 0; f < 30; ++f) {
    Eigen::VectorXd w = neutral;
    if (f % 2 == 1)
      for (int k = 0; k < kWeights; ++k) w[k] += amount(random);
    driver.push_back(w);
  }
  const std::vector<Eigen::VectorXd> tracked = driver;
  ASSERT_TRUE(ApplyDriveRemedy(DriveRemedy::kRelative, DriveRemedyOptions(), avatar, &driver).ok());
  const Eigen::VectorXd mean = Mean(avatar);
  for (int f = 0; f < 30; ++f) {
    if (f % 2 == 0) {
      EXPECT_LT((driver[f] - mean).cwiseAbs().maxCoeff(), 1e-12) << "frame " << f;
      continue;
    }
    // The expression's excursion kept where nothing clamps it.
    for (int k = 0; k < kWeights; ++k) {
      const double expected = tracked[f][k] - neutral[k] + mean[k];
      if (expected <= 1) {
        EXPECT_NEAR(driver[f][k], expected, 1e-12);
      }
    }
  }
}

TEST(DriveRemedy, PercentileInterpolatesBetweenOrderStatistics) {
  std::vector<Eigen::VectorXd> frames;
  for (double v : {0.4, 0.0, 0.2, 0.1, 0.3}) frames.push_back(Eigen::VectorXd::Constant(1, v));
  EXPECT_NEAR(PercentileWeights(frames, 0)[0], 0.0, 1e-12);
  EXPECT_NEAR(PercentileWeights(frames, 50)[0], 0.2, 1e-12);
  EXPECT_NEAR(PercentileWeights(frames, 10)[0], 0.04, 1e-12);
  EXPECT_NEAR(PercentileWeights(frames, 100)[0], 0.4, 1e-12);
}

TEST(DriveRemedy, TheSpanKeepsWhatIsInItAndDropsWhatIsNot) {
  const std::vector<Eigen::VectorXd> avatar = AvatarTraining();
  const ExpressionSpan span = FitExpressionSpan(avatar, 0.99);
  EXPECT_EQ(span.basis.cols(), 2);  // the two expression directions
  EXPECT_LT((span.basis.transpose() * span.basis - Eigen::MatrixXd::Identity(2, 2)).cwiseAbs().maxCoeff(), 1e-12);
  for (const Eigen::VectorXd& w : avatar) EXPECT_LT((span.Project(w) - w).cwiseAbs().maxCoeff(), 1e-12);
  // Off the span: its component along a direction training never used goes.
  Eigen::VectorXd off = avatar[3];
  Eigen::VectorXd direction = Eigen::VectorXd::Zero(kWeights);
  direction[3] = 1;
  direction -= span.basis * (span.basis.transpose() * direction);
  EXPECT_LT((span.Project(off + 0.1 * direction) - off).cwiseAbs().maxCoeff(), 1e-12);
  // relative+span on a driver whose weights already sit in the span (its
  // neutral the avatar's mean's own rest): unchanged.
  std::vector<Eigen::VectorXd> driver = avatar;
  ASSERT_TRUE(ApplyDriveRemedy(DriveRemedy::kRelativeSpan, DriveRemedyOptions(), avatar, &driver).ok());
  const Eigen::VectorXd shift = Mean(avatar) - PercentileWeights(avatar, 10);
  for (size_t f = 0; f < avatar.size(); ++f) {
    const Eigen::VectorXd expected = (avatar[f] + shift).cwiseMax(0.0).cwiseMin(1.0);
    EXPECT_LT((driver[f] - span.Project(expected).cwiseMax(0.0).cwiseMin(1.0)).cwiseAbs().maxCoeff(), 1e-12);
  }
}

TEST(DriveRemedy, ClampsToTheUnitInterval) {
  const std::vector<Eigen::VectorXd> still = {Eigen::Vector2d(0.5, 0.5), Eigen::Vector2d(0.5, 0.5)};
  const std::vector<Eigen::VectorXd> take = {Eigen::Vector2d(0.1, 0.1), Eigen::Vector2d(0.95, 0.1)};
  DriveRemedyOptions options;
  // The driver's neutral its lowest value, 0.1: 0.95 lands at 1.35, clamped to 1.
  options.neutral_percentile = 0;
  std::vector<Eigen::VectorXd> driver = take;
  ASSERT_TRUE(ApplyDriveRemedy(DriveRemedy::kRelative, options, still, &driver).ok());
  EXPECT_DOUBLE_EQ(driver[0][0], 0.5);
  EXPECT_DOUBLE_EQ(driver[1][0], 1.0);
  // Its neutral its highest value, 0.95: 0.1 lands at -0.35, clamped to 0.
  options.neutral_percentile = 100;
  driver = take;
  ASSERT_TRUE(ApplyDriveRemedy(DriveRemedy::kRelative, options, still, &driver).ok());
  EXPECT_DOUBLE_EQ(driver[0][0], 0.0);
  EXPECT_DOUBLE_EQ(driver[1][0], 0.5);
  // The span clamps too: the avatar's expressions on the line through
  // (0, 0.4) and (1, 0.6); (1, 1) projects onto (1.077, 0.615), then (1, 0.615).
  const std::vector<Eigen::VectorXd> line = {Eigen::Vector2d(0.0, 0.4), Eigen::Vector2d(1.0, 0.6)};
  driver = {Eigen::Vector2d(0.0, 0.0), Eigen::Vector2d(0.5, 0.5)};
  options.neutral_percentile = 0;
  ASSERT_TRUE(ApplyDriveRemedy(DriveRemedy::kRelativeSpan, options, line, &driver).ok());
  EXPECT_NEAR(driver[0][0], 0.5, 1e-12);
  EXPECT_NEAR(driver[0][1], 0.5, 1e-12);
  EXPECT_DOUBLE_EQ(driver[1][0], 1.0);
  EXPECT_NEAR(driver[1][1], 0.5 + 0.2 * 0.6 / 1.04, 1e-12);
  // Refused: nothing to re-base on, a percentile out of range.
  EXPECT_FALSE(ApplyDriveRemedy(DriveRemedy::kRelative, options, {}, &driver).ok());
  options.neutral_percentile = 120;
  EXPECT_FALSE(ApplyDriveRemedy(DriveRemedy::kRelative, options, still, &driver).ok());
}

}  // namespace
}  // namespace headforge
