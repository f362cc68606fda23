// Status: the outcome of an operation that can fail for expected reasons (a
// missing file, a video with no face, a bad option). Broken invariants throw
// instead; library code never exits the process.
#pragma once

#include <string>
#include <utility>

namespace headforge {

class Status {
 public:
  enum class Code {
    kOk = 0,
    kInvalidArgument,  // a bad option or argument: the user must change the call
    kNotFound,         // a named file or folder does not exist
    kDataError,        // the input exists but cannot be used (corrupt, no face, ...)
    kIoError,          // reading or writing failed (permissions, full disk)
    kInterrupted,      // stopped on request (SIGINT, SIGTERM) after saving what resumes it
    kInternal,         // anything else
  };

  Status() = default;
  static Status Ok() { return Status(); }
  static Status InvalidArgument(std::string m) { return Status(Code::kInvalidArgument, std::move(m)); }
  static Status NotFound(std::string m) { return Status(Code::kNotFound, std::move(m)); }
  static Status DataError(std::string m) { return Status(Code::kDataError, std::move(m)); }
  static Status IoError(std::string m) { return Status(Code::kIoError, std::move(m)); }
  static Status Interrupted(std::string m) { return Status(Code::kInterrupted, std::move(m)); }
  static Status Internal(std::string m) { return Status(Code::kInternal, std::move(m)); }

  bool ok() const { return code_ == Code::kOk; }
  Code code() const { return code_; }
  const std::string& message() const { return message_; }

  // The same error with another message.
  Status WithMessage(std::string message) const {
    if (ok()) return *this;
    return Status(code_, std::move(message));
  }

  // Prefixes the message with context ("ingest: " + message), once: a
  // message that already starts with it is left as it is.
  Status WithContext(const std::string& context) const {
    if (ok()) return *this;
    const std::string prefix = context + ": ";
    if (message_.compare(0, prefix.size(), prefix) == 0) return *this;
    return Status(code_, prefix + message_);
  }

 private:
  Status(Code code, std::string message) : code_(code), message_(std::move(message)) {}
  Code code_ = Code::kOk;
  std::string message_;
};

// Returns from the enclosing function when `expr` yields a non-ok Status.
#define HF_RETURN_IF_ERROR(expr)                  \
  do {                                            \
    ::headforge::Status hf_status_ = (expr);      \
    if (!hf_status_.ok()) return hf_status_;      \
  } while (0)

// Throws std::logic_error naming the failed invariant (a bug, not bad input).
#define HF_CHECK(cond)                                                        \
  do {                                                                        \
    if (!(cond))                                                              \
      ::headforge::internal::CheckFailed(#cond, __FILE__, __LINE__);          \
  } while (0)

namespace internal {
[[noreturn]] void CheckFailed(const char* condition, const char* file, int line);
}  // namespace internal

}  // namespace headforge
