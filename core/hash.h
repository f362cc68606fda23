// Fingerprints: 64-bit hashes of options and inputs that decide whether a stage
// must run again. Not cryptographic; collisions only cost a skipped re-run.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "core/fs.h"
#include "core/status.h"

namespace headforge {

class Hasher {
 public:
  Hasher& Add(const void* data, size_t size);
  Hasher& Add(const std::string& text);
  Hasher& Add(int64_t value);
  // Adds the full contents of a file.
  Status AddFileContents(const fs::path& path);
  // Adds a file's name, size and modification time (cheap; changes when the
  // file is rewritten, copied or moved, even with the same contents).
  Status AddFileStamp(const fs::path& path);
  // Adds what a file holds, wherever it lies: its contents up to 16 MiB,
  // beyond that its size and 64 blocks of 64 KiB spread over it (model
  // files: a copied or reinstalled model reads as the same one).
  Status AddFileDigest(const fs::path& path);
  // Adds every regular file under `dir` (relative name and contents), sorted.
  Status AddTreeContents(const fs::path& dir);

  uint64_t value() const;
  // 16 lower-case hex digits.
  std::string Hex() const;

 private:
  uint64_t state_ = 0xcbf29ce484222325ULL;  // FNV-1a offset basis
  uint64_t length_ = 0;
};

}  // namespace headforge
