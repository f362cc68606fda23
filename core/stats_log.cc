#include "core/stats_log.h"

#include <sstream>

namespace headforge {

Status StatsLog::Open(const fs::path& path, StatsLog* log) {
  log->path_ = path;
  log->lines_.clear();
  std::error_code ec;
  if (fs::exists(path, ec)) {
    std::string text;
    HF_RETURN_IF_ERROR(ReadFileToString(path, &text));
    std::istringstream in(text);
    // A line cut short by a kill has no newline: it is dropped.
    for (std::string line; std::getline(in, line);)
      if (!in.eof()) log->lines_.push_back(line);
  }
  return log->Truncate(log->lines_.size());
}

void StatsLog::Append(const std::string& line) {
  lines_.push_back(line);
  if (out_.is_open()) out_ << line << '\n' << std::flush;
}

Status StatsLog::Truncate(size_t count) {
  if (count < lines_.size()) lines_.resize(count);
  if (path_.empty()) return Status::Ok();
  if (out_.is_open()) out_.close();
  std::string text;
  for (const auto& line : lines_) text += line + "\n";
  HF_RETURN_IF_ERROR(WriteFileAtomic(path_, text));
  out_.open(path_, std::ios::app);
  if (!out_) return Status::IoError("cannot append to " + path_.string());
  return Status::Ok();
}

}  // namespace headforge
