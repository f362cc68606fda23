#include "export/gaussian_ply.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <cstring>
#include <random>

namespace headforge {
namespace {

GaussianCloud RandomCloud(size_t n, int degree, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<float> normal;
  GaussianCloud c;
  c.sh_degree = degree;
  auto fill = [&](std::vector<float>* v, size_t size) {
    v->resize(size);
    for (auto& x : *v) x = normal(rng);
  };
  fill(&c.means, 3 * n);
  fill(&c.sh_dc, 3 * n);
  fill(&c.sh_rest, 3 * n * c.RestPerChannel());
  fill(&c.opacities, n);
  fill(&c.log_scales, 3 * n);
  fill(&c.rotations, 4 * n);
  return c;
}

bool BitEqual(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
}

fs::path Temp(const std::string& name) { return fs::temp_directory_path() / ("hf_ply_" + name); }

TEST(GaussianPly, RoundTripIsExact) {
  const GaussianCloud cloud = RandomCloud(1000, 3, 1);
  ASSERT_TRUE(WriteGaussianPly(Temp("d3.ply"), cloud).ok());
  GaussianCloud back;
  ASSERT_TRUE(ReadGaussianPly(Temp("d3.ply"), &back).ok());
  EXPECT_EQ(back.sh_degree, 3);
  EXPECT_TRUE(BitEqual(back.means, cloud.means));
  EXPECT_TRUE(BitEqual(back.sh_dc, cloud.sh_dc));
  EXPECT_TRUE(BitEqual(back.sh_rest, cloud.sh_rest));
  EXPECT_TRUE(BitEqual(back.opacities, cloud.opacities));
  EXPECT_TRUE(BitEqual(back.log_scales, cloud.log_scales));
  EXPECT_TRUE(BitEqual(back.rotations, cloud.rotations));
  // The file is exactly header + 62 floats per Gaussian.
  std::string bytes;
  ASSERT_TRUE(ReadFileToString(Temp("d3.ply"), &bytes).ok());
  const size_t header = bytes.find("end_header\n") + 11;
  EXPECT_EQ(bytes.size() - header, 1000u * 62 * 4);
  EXPECT_NE(bytes.find("property float f_rest_44\n"), std::string::npos);
}

TEST(GaussianPly, LowerDegreesArePaddedToDegreeThree) {
  const GaussianCloud cloud = RandomCloud(10, 1, 2);
  ASSERT_TRUE(WriteGaussianPly(Temp("d1.ply"), cloud).ok());
  GaussianCloud back;
  ASSERT_TRUE(ReadGaussianPly(Temp("d1.ply"), &back).ok());
  ASSERT_EQ(back.sh_degree, 3);
  for (size_t i = 0; i < 10; ++i)
    for (int c = 0; c < 3; ++c)
      for (int j = 0; j < 15; ++j) {
        const float expected = j < 3 ? cloud.sh_rest[(i * 3 + c) * 3 + j] : 0.0f;
        EXPECT_EQ(back.sh_rest[(i * 3 + c) * 15 + j], expected);
      }
}

TEST(GaussianPly, EmptyCloudAndBadFiles) {
  GaussianCloud empty;
  ASSERT_TRUE(WriteGaussianPly(Temp("empty.ply"), empty).ok());
  GaussianCloud back;
  ASSERT_TRUE(ReadGaussianPly(Temp("empty.ply"), &back).ok());
  EXPECT_EQ(back.size(), 0u);

  GaussianCloud broken = RandomCloud(3, 0, 3);
  broken.opacities.pop_back();
  EXPECT_EQ(WriteGaussianPly(Temp("broken.ply"), broken).code(), Status::Code::kInvalidArgument);

  const GaussianCloud cloud = RandomCloud(100, 0, 4);
  ASSERT_TRUE(WriteGaussianPly(Temp("cut.ply"), cloud).ok());
  std::string bytes;
  ASSERT_TRUE(ReadFileToString(Temp("cut.ply"), &bytes).ok());
  ASSERT_TRUE(WriteFileAtomic(Temp("cut.ply"), bytes.substr(0, bytes.size() - 100)).ok());
  Status s = ReadGaussianPly(Temp("cut.ply"), &back);
  EXPECT_EQ(s.code(), Status::Code::kDataError);
  EXPECT_NE(s.message().find("truncated"), std::string::npos);

  ASSERT_TRUE(WriteFileAtomic(Temp("ascii.ply"), "ply\nformat ascii 1.0\nelement vertex 0\nend_header\n").ok());
  s = ReadGaussianPly(Temp("ascii.ply"), &back);
  EXPECT_NE(s.message().find("ascii"), std::string::npos);
  ASSERT_TRUE(WriteFileAtomic(Temp("nope.ply"), "not a ply").ok());
  EXPECT_EQ(ReadGaussianPly(Temp("nope.ply"), &back).code(), Status::Code::kDataError);
  ASSERT_TRUE(WriteFileAtomic(Temp("points.ply"),
                              "ply\nformat binary_little_endian 1.0\nelement vertex 0\nproperty float x\nproperty float y\n"
                              "property float z\nend_header\n").ok());
  s = ReadGaussianPly(Temp("points.ply"), &back);
  EXPECT_NE(s.message().find("f_dc_0"), std::string::npos) << s.message();
}

#ifdef HEADFORGE_SPLAT_TRANSFORM
// A viewer-side tool reads the file and counts the Gaussians.
TEST(GaussianPly, SplatTransformReadsTheExportedFile) {
  const GaussianCloud cloud = RandomCloud(1234, 0, 5);
  ASSERT_TRUE(WriteGaussianPly(Temp("viewer.ply"), cloud).ok());
  const fs::path out = Temp("viewer_info.json");
  const std::string command = std::string("'") + HEADFORGE_SPLAT_TRANSFORM + "' -q '" + Temp("viewer.ply").string() +
                              "' null --info json > '" + out.string() + "' 2>&1";
  ASSERT_EQ(std::system(command.c_str()), 0) << command;
  std::string info;
  ASSERT_TRUE(ReadFileToString(out, &info).ok());
  EXPECT_NE(info.find("\"numGaussians\": 1234"), std::string::npos) << info;
  EXPECT_NE(info.find("\"shBands\": 3"), std::string::npos) << info;
}
#endif

}  // namespace
}  // namespace headforge
