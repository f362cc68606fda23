// Plain logging to stderr for the command-line tool. Library code logs through
// these functions (never std::cout), so a caller can silence or redirect it.
#pragma once

#include <functional>
#include <sstream>
#include <string>

namespace headforge {

enum class LogLevel { kDebug = 0, kInfo = 1, kWarning = 2, kError = 3, kSilent = 4 };

void SetLogLevel(LogLevel level);
LogLevel GetLogLevel();
// Replaces the sink (default: stderr with a level tag); tests capture with it.
void SetLogSink(std::function<void(LogLevel, const std::string&)> sink);
void ResetLogSink();
void LogMessage(LogLevel level, const std::string& message);

namespace internal {
class LogLine {
 public:
  explicit LogLine(LogLevel level) : level_(level) {}
  ~LogLine() { LogMessage(level_, stream_.str()); }
  template <typename T>
  LogLine& operator<<(const T& value) {
    stream_ << value;
    return *this;
  }

 private:
  LogLevel level_;
  std::ostringstream stream_;
};
}  // namespace internal

}  // namespace headforge

#define HF_LOG(level) ::headforge::internal::LogLine(::headforge::LogLevel::k##level)
