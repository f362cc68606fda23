#include "core/fs.h"

#include <gtest/gtest.h>

namespace headforge {
namespace {

TEST(Fs, AtomicWriteLeavesNoTemporaryFiles) {
  const fs::path dir = fs::temp_directory_path() / "hf_fs_test";
  fs::remove_all(dir);
  ASSERT_TRUE(WriteFileAtomic(dir / "sub" / "f.txt", "one").ok());
  ASSERT_TRUE(WriteFileAtomic(dir / "sub" / "f.txt", "two").ok());
  std::string text;
  ASSERT_TRUE(ReadFileToString(dir / "sub" / "f.txt", &text).ok());
  EXPECT_EQ(text, "two");
  int count = 0;
  for (const auto& entry : fs::directory_iterator(dir / "sub")) {
    (void)entry;
    ++count;
  }
  EXPECT_EQ(count, 1);
  fs::remove_all(dir);
}

TEST(Fs, ReplacePathSwapsFolders) {
  const fs::path dir = fs::temp_directory_path() / "hf_fs_replace";
  fs::remove_all(dir);
  ASSERT_TRUE(WriteFileAtomic(dir / "old" / "a", "old").ok());
  ASSERT_TRUE(WriteFileAtomic(dir / "new" / "b", "new").ok());
  ASSERT_TRUE(ReplacePath(dir / "new", dir / "old").ok());
  EXPECT_FALSE(fs::exists(dir / "old" / "a"));
  EXPECT_TRUE(fs::exists(dir / "old" / "b"));
  EXPECT_FALSE(fs::exists(dir / "new"));
  fs::remove_all(dir);
}

TEST(Fs, WriteIntoUnwritableFolderFailsWithIoError) {
  if (::geteuid() == 0) {
    // root ignores permission bits; /proc is unwritable for everybody.
    const Status status = WriteFileAtomic("/proc/headforge_test/x", "data");
    EXPECT_FALSE(status.ok());
    return;
  }
  const fs::path dir = fs::temp_directory_path() / "hf_fs_ro";
  fs::create_directories(dir);
  fs::permissions(dir, fs::perms::owner_read | fs::perms::owner_exec);
  const Status status = WriteFileAtomic(dir / "x", "data");
  EXPECT_EQ(status.code(), Status::Code::kIoError);
  fs::permissions(dir, fs::perms::owner_all);
  fs::remove_all(dir);
}

TEST(Fs, CheckReadableFile) {
  EXPECT_EQ(CheckReadableFile("/no/such/file", "video").code(), Status::Code::kNotFound);
  EXPECT_EQ(CheckReadableFile(fs::temp_directory_path(), "video").code(),
            Status::Code::kInvalidArgument);
}

}  // namespace
}  // namespace headforge
