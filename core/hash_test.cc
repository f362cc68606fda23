#include "core/hash.h"

#include <gtest/gtest.h>

#include <chrono>
#include <string>

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

// A model file's digest follows its contents, not where it lies or when it
// was written: a copy elsewhere, touched, digests the same; a byte changed
// in a sampled block, or the size, does not.
TEST(Hasher, FileDigestFollowsContentsNotPlaceOrTime) {
  const fs::path dir = fs::temp_directory_path() / "hf_hash_digest_test";
  fs::remove_all(dir);
  fs::create_directories(dir / "copy");
  auto digest = [](const fs::path& path) {
    Hasher h;
    EXPECT_TRUE(h.AddFileDigest(path).ok()) << path;
    return h.Hex();
  };
  for (const size_t size : {size_t(1000), (size_t(20) << 20) + 12345}) {  // whole, and sampled
    std::string bytes(size, '\0');
    for (size_t i = 0; i < size; ++i) bytes[i] = char((i * 2654435761u) >> 13);
    ASSERT_TRUE(WriteFileAtomic(dir / "model.bin", bytes).ok());
    fs::copy_file(dir / "model.bin", dir / "copy" / "model.bin", fs::copy_options::overwrite_existing);
    fs::last_write_time(dir / "copy" / "model.bin", fs::last_write_time(dir / "model.bin") - std::chrono::hours(24));
    EXPECT_EQ(digest(dir / "model.bin"), digest(dir / "copy" / "model.bin")) << size;
    bytes[0] ^= 1;  // the first block is always read
    ASSERT_TRUE(WriteFileAtomic(dir / "copy" / "model.bin", bytes).ok());
    EXPECT_NE(digest(dir / "model.bin"), digest(dir / "copy" / "model.bin")) << size;
    bytes[0] ^= 1;
    bytes.push_back('x');
    ASSERT_TRUE(WriteFileAtomic(dir / "copy" / "model.bin", bytes).ok());
    EXPECT_NE(digest(dir / "model.bin"), digest(dir / "copy" / "model.bin")) << size;
  }
  Hasher missing;
  EXPECT_EQ(missing.AddFileDigest(dir / "missing").code(), Status::Code::kNotFound);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace headforge
