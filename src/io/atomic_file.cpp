#include "unsup_mvs/io/atomic_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <streambuf>

#include "unsup_mvs/io/file_safety.h"

namespace umvs {

namespace fs = std::filesystem;

namespace {

// An output stream buffer over a file descriptor we opened ourselves (std::ofstream can only open
// by name, which would follow whatever was planted under that name in between).
class FdOutBuf : public std::streambuf {
 public:
  explicit FdOutBuf(int fd) : fd_(fd) { setp(buf_, buf_ + sizeof(buf_)); }
  ~FdOutBuf() override { sync(); }

 protected:
  int_type overflow(int_type c) override {
    if (!flush_buffer()) return traits_type::eof();
    if (!traits_type::eq_int_type(c, traits_type::eof())) {
      *pptr() = traits_type::to_char_type(c);
      pbump(1);
    }
    return traits_type::not_eof(c);
  }
  int sync() override { return flush_buffer() ? 0 : -1; }

 private:
  bool flush_buffer() {
    for (const char* p = pbase(); p < pptr();) {
      const ssize_t n = ::write(fd_, p, static_cast<size_t>(pptr() - p));
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) return false;
      p += n;
    }
    setp(buf_, buf_ + sizeof(buf_));
    return true;
  }
  int fd_;
  char buf_[1 << 16];
};

}  // namespace

void write_file_atomically(const std::string& path, const std::function<void(std::ostream&)>& write) {
  const fs::path target(path);
  if (target.has_parent_path()) make_directories(target.parent_path().string());
  struct stat st;
  if (::lstat(path.c_str(), &st) == 0 && !S_ISREG(st.st_mode)) {
    throw std::runtime_error("'" + path + "' exists and is " + (S_ISLNK(st.st_mode) ? "a symbolic link" : "not a regular file") +
                             "; refusing to replace it");
  }
  int fd = -1;
  const std::string tmp = create_temp_file_beside(path, &fd);
  try {
    {
      FdOutBuf buf(fd);
      std::ostream out(&buf);
      write(out);
      out.flush();
      if (!out) throw std::runtime_error("error while writing '" + tmp + "' (disk full?)");
    }
    if (::fsync(fd) != 0) throw std::runtime_error("error while writing '" + tmp + "': " + std::strerror(errno));
    ::close(fd);
    fd = -1;
    // rename() replaces the name itself: it never follows a symlink planted at `path` meanwhile.
    if (::rename(tmp.c_str(), path.c_str()) != 0) {
      throw std::runtime_error("cannot rename '" + tmp + "' to '" + path + "': " + std::strerror(errno));
    }
  } catch (...) {
    if (fd >= 0) ::close(fd);
    ::unlink(tmp.c_str());
    throw;
  }
}

void make_directories(const std::string& path) {
  std::error_code ec;
  fs::create_directories(path, ec);
  if (ec) throw std::runtime_error("cannot create folder '" + path + "': " + ec.message());
}

std::string read_file_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error("cannot open '" + path + "': " + std::strerror(errno));
  std::ostringstream ss;
  ss << in.rdbuf();
  if (in.bad()) throw std::runtime_error("error while reading '" + path + "'");
  return ss.str();
}

}  // namespace umvs
