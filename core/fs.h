// File-system helpers that keep the workspace consistent: every file is written
// to a temporary name in its folder and renamed, so a reader (or a resumed run)
// never sees half a file.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "core/status.h"

namespace headforge {

namespace fs = std::filesystem;

// Writes `contents` to `path` through a temporary sibling, flushed, then renamed.
// A full disk or a read-only folder comes back as an IoError naming the path.
Status WriteFileAtomic(const fs::path& path, const std::string& contents);
Status ReadFileToString(const fs::path& path, std::string* contents);

// Creates `dir` and its parents if missing.
Status EnsureDirectory(const fs::path& dir);
// Removes `path` (file or tree) if it exists.
Status RemoveAll(const fs::path& path);
// Moves `source` onto `target`, replacing a previous file or folder there.
Status ReplacePath(const fs::path& source, const fs::path& target);

// Checks that `path` names an existing regular file we can open for reading.
Status CheckReadableFile(const fs::path& path, const std::string& what);

// Regular files in `dir` (not recursive), sorted by name, optionally filtered
// by lower-case extension (".png").
std::vector<fs::path> ListFiles(const fs::path& dir, const std::vector<std::string>& extensions = {});

// The canonical absolute form of `path` when it exists, else its absolute form.
fs::path AbsolutePath(const fs::path& path);

}  // namespace headforge
