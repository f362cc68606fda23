#include "core/hash.h"

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <vector>

namespace headforge {

Hasher& Hasher::Add(const void* data, size_t size) {
  // FNV-1a, then a length-aware finaliser in value().
  const auto* bytes = static_cast<const unsigned char*>(data);
  uint64_t h = state_;
  for (size_t i = 0; i < size; ++i) {
    h ^= bytes[i];
    h *= 0x100000001b3ULL;
  }
  state_ = h;
  length_ += size;
  return *this;
}

Hasher& Hasher::Add(const std::string& text) {
  const int64_t n = static_cast<int64_t>(text.size());
  Add(&n, sizeof(n));  // length prefix keeps ("ab","c") apart from ("a","bc")
  return Add(text.data(), text.size());
}

Hasher& Hasher::Add(int64_t value) { return Add(&value, sizeof(value)); }

Status Hasher::AddFileContents(const fs::path& path) {
  HF_RETURN_IF_ERROR(CheckReadableFile(path, "file"));
  std::ifstream in(path, std::ios::binary);
  std::vector<char> buffer(1 << 20);
  while (in) {
    in.read(buffer.data(), static_cast<std::streamsize>(buffer.size()));
    Add(buffer.data(), static_cast<size_t>(in.gcount()));
  }
  if (in.bad()) return Status::IoError("error while reading " + path.string());
  return Status::Ok();
}

Status Hasher::AddFileStamp(const fs::path& path) {
  std::error_code ec;
  const auto size = fs::file_size(path, ec);
  if (ec) return Status::NotFound("cannot stat " + path.string() + ": " + ec.message());
  const auto time = fs::last_write_time(path, ec).time_since_epoch().count();
  Add(AbsolutePath(path).string());
  Add(static_cast<int64_t>(size));
  Add(static_cast<int64_t>(time));
  return Status::Ok();
}

Status Hasher::AddFileDigest(const fs::path& path) {
  constexpr uintmax_t kWhole = uintmax_t(16) << 20;
  constexpr size_t kBlock = size_t(64) << 10;
  constexpr int kBlocks = 64;
  HF_RETURN_IF_ERROR(CheckReadableFile(path, "file"));
  std::error_code ec;
  const uintmax_t size = fs::file_size(path, ec);
  if (ec) return Status::NotFound("cannot stat " + path.string() + ": " + ec.message());
  if (size <= kWhole) return AddFileContents(path);
  Add(static_cast<int64_t>(size));
  std::ifstream in(path, std::ios::binary);
  std::vector<char> buffer(kBlock);
  for (int i = 0; i < kBlocks; ++i) {
    // From the first block to the last, evenly.
    const uintmax_t at = (size - kBlock) * uintmax_t(i) / (kBlocks - 1);
    in.seekg(static_cast<std::streamoff>(at));
    in.read(buffer.data(), static_cast<std::streamsize>(kBlock));
    if (in.gcount() != static_cast<std::streamsize>(kBlock))
      return Status::IoError("error while reading " + path.string());
    Add(buffer.data(), kBlock);
  }
  return Status::Ok();
}

Status Hasher::AddTreeContents(const fs::path& dir) {
  std::error_code ec;
  std::vector<fs::path> files;
  for (auto it = fs::recursive_directory_iterator(dir, ec); !ec && it != fs::end(it);
       it.increment(ec)) {
    std::error_code type_ec;  // a file that vanished or cannot be read is not one to hash
    if (it->is_regular_file(type_ec)) files.push_back(it->path());
  }
  if (ec) return Status::IoError("cannot list " + dir.string() + ": " + ec.message());
  std::sort(files.begin(), files.end());
  for (const auto& file : files) {
    Add(fs::relative(file, dir).string());
    HF_RETURN_IF_ERROR(AddFileContents(file));
  }
  return Status::Ok();
}

uint64_t Hasher::value() const {
  // splitmix64 finaliser over state and length.
  uint64_t z = state_ ^ (length_ * 0x9e3779b97f4a7c15ULL);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

std::string Hasher::Hex() const {
  char text[17];
  std::snprintf(text, sizeof(text), "%016llx", static_cast<unsigned long long>(value()));
  return text;
}

}  // namespace headforge
