// stats.jsonl: one JSON object per line, appended as long work goes on (a
// training loop's losses, its held-out scores), flushed line by line so that
// a report can plot it while the work runs. A run that resumes from a
// checkpoint cuts the file back to the lines the checkpoint had seen.
#pragma once

#include <fstream>
#include <string>
#include <vector>

#include "core/fs.h"
#include "core/status.h"

namespace headforge {

class StatsLog {
 public:
  // Lines kept in memory only.
  StatsLog() = default;
  // Appends to `path` (created when missing).
  static Status Open(const fs::path& path, StatsLog* log);

  // Appends one line (a JSON object's text, without the newline).
  void Append(const std::string& line);
  // Keeps the first `count` lines (a checkpoint's), dropping later ones.
  Status Truncate(size_t count);

  size_t size() const { return lines_.size(); }
  const std::vector<std::string>& lines() const { return lines_; }

 private:
  fs::path path_;
  std::ofstream out_;
  std::vector<std::string> lines_;
};

}  // namespace headforge
