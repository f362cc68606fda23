#include "core/hash.h"

#include <gtest/gtest.h>

namespace headforge {
namespace {

TEST(Hasher, DeterministicAndSensitive) {
  EXPECT_EQ(Hasher().Add(std::string("abc")).Hex(), Hasher().Add(std::string("abc")).Hex());
  EXPECT_NE(Hasher().Add(std::string("abc")).Hex(), Hasher().Add(std::string("abd")).Hex());
  // Length prefixes keep concatenations apart.
  EXPECT_NE(Hasher().Add(std::string("ab")).Add(std::string("c")).Hex(),
            Hasher().Add(std::string("a")).Add(std::string("bc")).Hex());
  EXPECT_EQ(Hasher().Hex().size(), 16u);
}

TEST(Hasher, FileContents) {
  const fs::path dir = fs::temp_directory_path() / "hf_hash_test";
  fs::create_directories(dir);
  ASSERT_TRUE(WriteFileAtomic(dir / "a.txt", "hello").ok());
  Hasher h1, h2, h3;
  ASSERT_TRUE(h1.AddFileContents(dir / "a.txt").ok());
  ASSERT_TRUE(h2.AddTreeContents(dir).ok());
  ASSERT_TRUE(WriteFileAtomic(dir / "a.txt", "hellO").ok());
  ASSERT_TRUE(h3.AddFileContents(dir / "a.txt").ok());
  EXPECT_NE(h1.Hex(), h3.Hex());
  Hasher missing;
  EXPECT_EQ(missing.AddFileContents(dir / "missing").code(), Status::Code::kNotFound);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace headforge
