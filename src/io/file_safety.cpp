#include "unsup_mvs/io/file_safety.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <stdexcept>

namespace umvs {

namespace fs = std::filesystem;

namespace {

std::string errno_text() { return std::strerror(errno); }

class Fd {
 public:
  explicit Fd(int fd) : fd_(fd) {}
  ~Fd() {
    if (fd_ >= 0) ::close(fd_);
  }
  Fd(const Fd&) = delete;
  Fd& operator=(const Fd&) = delete;
  int get() const { return fd_; }

 private:
  int fd_;
};

// The mode a plain open(O_CREAT, 0666) would give: mkostemp creates files as 0600.
mode_t new_file_mode() {
  std::ifstream status("/proc/self/status");
  for (std::string line; std::getline(status, line);) {
    if (line.rfind("Umask:", 0) == 0) return 0666 & ~static_cast<mode_t>(std::stoul(line.substr(6), nullptr, 8));
  }
  return 0644;
}

}  // namespace

std::string create_temp_file_beside(const std::string& path, int* fd) {
  std::string name = path + kTempInfix + "XXXXXX";
  // mkostemp opens with O_CREAT|O_EXCL: a name that exists (a file or a planted symlink) is never
  // opened, and the random suffix cannot be predicted.
  *fd = ::mkostemp(name.data(), O_CLOEXEC);
  if (*fd < 0) throw std::runtime_error("cannot create a temporary file beside '" + path + "': " + errno_text());
  ::fchmod(*fd, new_file_mode());
  return name;
}

void copy_file_to_new_name(const std::string& from, const std::string& to) {
  struct stat st;
  if (::lstat(to.c_str(), &st) == 0) throw std::runtime_error("'" + to + "' already exists; refusing to replace it");
  const Fd in(::open(from.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK));
  if (in.get() < 0) throw std::runtime_error("cannot open '" + from + "': " + errno_text());
  if (::fstat(in.get(), &st) != 0 || !S_ISREG(st.st_mode)) throw std::runtime_error("'" + from + "' is not a regular file");
  int out_fd = -1;
  const std::string tmp = create_temp_file_beside(to, &out_fd);
  const Fd out(out_fd);
  try {
    char buf[1 << 16];
    for (;;) {
      const ssize_t n = ::read(in.get(), buf, sizeof(buf));
      if (n < 0 && errno == EINTR) continue;
      if (n < 0) throw std::runtime_error("error while reading '" + from + "': " + errno_text());
      if (n == 0) break;
      for (ssize_t done = 0; done < n;) {
        const ssize_t w = ::write(out.get(), buf + done, static_cast<size_t>(n - done));
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0) throw std::runtime_error("error while writing '" + tmp + "' (disk full?): " + errno_text());
        done += w;
      }
    }
    if (::fsync(out.get()) != 0) throw std::runtime_error("error while writing '" + tmp + "': " + errno_text());
    // link() fails with EEXIST whatever appeared under the final name (file or link): nothing is replaced.
    if (::link(tmp.c_str(), to.c_str()) != 0) {
      throw std::runtime_error(errno == EEXIST ? "'" + to + "' already exists; refusing to replace it"
                                               : "cannot create '" + to + "': " + errno_text());
    }
  } catch (...) {
    ::unlink(tmp.c_str());
    throw;
  }
  ::unlink(tmp.c_str());
}

bool path_inside(const std::string& path, const std::string& dir) {
  std::error_code ec;
  const fs::path p = fs::weakly_canonical(fs::absolute(path), ec);
  if (ec) return false;
  const fs::path d = fs::weakly_canonical(fs::absolute(dir), ec);
  if (ec) return false;
  auto pi = p.begin();
  for (auto di = d.begin(); di != d.end(); ++di, ++pi) {
    if (di->empty()) continue;  // trailing slash
    if (pi == p.end() || *pi != *di) return false;
  }
  return pi != p.end();  // strictly inside, not the folder itself
}

std::string resolve_inside(const std::string& dir, const std::string& requested) {
  if (requested.empty()) throw std::invalid_argument("empty path");
  const fs::path p = fs::path(requested).is_absolute() ? fs::path(requested) : fs::path(dir) / requested;
  if (!path_inside(p.string(), dir)) {
    std::error_code ec;
    const fs::path resolved = fs::weakly_canonical(fs::absolute(p), ec);
    throw std::invalid_argument("'" + requested + "' resolves to '" + (ec ? p : resolved).string() +
                                "', outside the allowed folder '" + dir + "'");
  }
  return p.lexically_normal().string();
}

int remove_stale_temp_files(const std::string& dir) {
  int removed = 0;
  std::error_code walk_ec;
  for (fs::recursive_directory_iterator it(dir, walk_ec), end; !walk_ec && it != end; it.increment(walk_ec)) {
    const std::string name = it->path().filename().string();
    if (name.find(kTempInfix) == std::string::npos) continue;
    // symlink_status: a planted link is removed as a link, its target is never touched.
    std::error_code ec;
    const auto type = it->symlink_status(ec).type();
    if (type != fs::file_type::regular && type != fs::file_type::symlink) continue;
    if (fs::remove(it->path(), ec)) ++removed;
  }
  return removed;
}

}  // namespace umvs
