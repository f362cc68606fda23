#include "core/fs.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <sstream>

namespace headforge {
namespace {

std::string ErrnoText(int err) {
  if (err == ENOSPC) return "no space left on the device (free some disk space and run again)";
  if (err == EDQUOT) return "disk quota exceeded";
  if (err == EFBIG)
    return "the file would pass the largest size allowed (a file-size limit such as ulimit -f, or a full disk; "
           "raise the limit or free space and run again)";
  if (err == EACCES || err == EPERM) return "permission denied";
  if (err == EROFS) return "read-only file system";
  return std::strerror(err);
}

fs::path TemporarySibling(const fs::path& path) {
  static std::atomic<unsigned> counter{0};
  return path.parent_path() /
         ("." + path.filename().string() + ".tmp" + std::to_string(::getpid()) + "_" +
          std::to_string(counter++));
}

}  // namespace

Status WriteFileAtomic(const fs::path& path, const std::string& contents) {
  if (path.has_parent_path()) HF_RETURN_IF_ERROR(EnsureDirectory(path.parent_path()));
  const fs::path tmp = TemporarySibling(path);
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) return Status::IoError("cannot write " + path.string() + ": " + ErrnoText(errno));
  const char* data = contents.data();
  size_t left = contents.size();
  while (left > 0) {
    const ssize_t n = ::write(fd, data, left);
    if (n < 0) {
      if (errno == EINTR) continue;
      const int err = errno;
      ::close(fd);
      ::unlink(tmp.c_str());
      return Status::IoError("cannot write " + path.string() + ": " + ErrnoText(err));
    }
    data += n;
    left -= static_cast<size_t>(n);
  }
  if (::fsync(fd) != 0 && errno != EINVAL) {
    const int err = errno;
    ::close(fd);
    ::unlink(tmp.c_str());
    return Status::IoError("cannot write " + path.string() + ": " + ErrnoText(err));
  }
  if (::close(fd) != 0) {
    const int err = errno;
    ::unlink(tmp.c_str());
    return Status::IoError("cannot write " + path.string() + ": " + ErrnoText(err));
  }
  if (::rename(tmp.c_str(), path.c_str()) != 0) {
    const int err = errno;
    ::unlink(tmp.c_str());
    return Status::IoError("cannot rename onto " + path.string() + ": " + ErrnoText(err));
  }
  return Status::Ok();
}

Status ReadFileToString(const fs::path& path, std::string* contents) {
  HF_RETURN_IF_ERROR(CheckReadableFile(path, "file"));
  std::ifstream in(path, std::ios::binary);
  std::ostringstream buffer;
  buffer << in.rdbuf();
  if (in.bad()) return Status::IoError("error while reading " + path.string());
  *contents = buffer.str();
  return Status::Ok();
}

Status EnsureDirectory(const fs::path& dir) {
  std::error_code ec;
  if (fs::is_directory(dir, ec)) return Status::Ok();
  fs::create_directories(dir, ec);
  if (ec) return Status::IoError("cannot create folder " + dir.string() + ": " + ec.message());
  return Status::Ok();
}

Status RemoveAll(const fs::path& path) {
  std::error_code ec;
  fs::remove_all(path, ec);
  if (ec) return Status::IoError("cannot remove " + path.string() + ": " + ec.message());
  return Status::Ok();
}

Status ReplacePath(const fs::path& source, const fs::path& target) {
  std::error_code ec;
  if (fs::is_directory(target, ec)) {
    // rename() cannot replace a non-empty folder: move the old one aside first.
    const fs::path old = TemporarySibling(target);
    fs::rename(target, old, ec);
    if (ec) return Status::IoError("cannot move " + target.string() + " aside: " + ec.message());
    fs::rename(source, target, ec);
    if (ec) {
      std::error_code ignored;
      fs::rename(old, target, ignored);
      return Status::IoError("cannot move " + source.string() + " to " + target.string() + ": " +
                             ec.message());
    }
    return RemoveAll(old);
  }
  if (target.has_parent_path()) HF_RETURN_IF_ERROR(EnsureDirectory(target.parent_path()));
  fs::rename(source, target, ec);
  if (ec)
    return Status::IoError("cannot move " + source.string() + " to " + target.string() + ": " +
                           ec.message());
  return Status::Ok();
}

Status CheckReadableFile(const fs::path& path, const std::string& what) {
  std::error_code ec;
  if (!fs::exists(path, ec)) return Status::NotFound(what + " not found: " + path.string());
  if (fs::is_directory(path, ec))
    return Status::InvalidArgument(what + " is a folder, expected a file: " + path.string());
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0)
    return Status::IoError("cannot read " + what + " " + path.string() + ": " + ErrnoText(errno));
  ::close(fd);
  return Status::Ok();
}

std::vector<fs::path> ListFiles(const fs::path& dir, const std::vector<std::string>& extensions) {
  std::vector<fs::path> files;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(dir, ec)) {
    if (!entry.is_regular_file()) continue;
    if (entry.path().filename().string().rfind('.', 0) == 0) continue;  // hidden
    if (!extensions.empty()) {
      std::string ext = entry.path().extension().string();
      std::transform(ext.begin(), ext.end(), ext.begin(), ::tolower);
      if (std::find(extensions.begin(), extensions.end(), ext) == extensions.end()) continue;
    }
    files.push_back(entry.path());
  }
  std::sort(files.begin(), files.end());
  return files;
}

fs::path AbsolutePath(const fs::path& path) {
  std::error_code ec;
  fs::path canonical = fs::weakly_canonical(path, ec);
  if (!ec) return canonical;
  return fs::absolute(path, ec);
}

}  // namespace headforge
