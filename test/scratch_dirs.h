// Temporary folders of a test process, removed when the process exits, so that running the tests
// again and again does not fill /tmp. UMVS_KEEP_TEST_DIRS=1 keeps them for a post-mortem. Shared
// by the gtest helpers (test_util.h) and the rostest helpers (ros/rostest_util.h).
#pragma once

#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <mutex>
#include <string>
#include <system_error>
#include <vector>

namespace umvs_scratch {

class ScratchDirs {
 public:
  // A fresh, empty folder <tmp>/<prefix><name>_<pid>.
  std::string make(const std::string& prefix, const std::string& name) {
    const auto p = std::filesystem::temp_directory_path() / (prefix + name + "_" + std::to_string(::getpid()));
    std::filesystem::remove_all(p);
    std::filesystem::create_directories(p);
    std::lock_guard<std::mutex> lock(mutex_);
    dirs_.push_back(p);
    return p.string();
  }

  ~ScratchDirs() {
    const char* keep = std::getenv("UMVS_KEEP_TEST_DIRS");
    // A forked child that exits normally must not remove its parent's folders.
    if (::getpid() != owner_ || (keep && std::string(keep) == "1")) return;
    for (const auto& p : dirs_) {
      std::error_code ignored;
      std::filesystem::remove_all(p, ignored);
    }
  }

 private:
  const pid_t owner_ = ::getpid();
  std::mutex mutex_;
  std::vector<std::filesystem::path> dirs_;
};

// One registry per process (an inline function's static is shared by all translation units).
inline std::string scratch_dir(const std::string& prefix, const std::string& name) {
  static ScratchDirs dirs;
  return dirs.make(prefix, name);
}

}  // namespace umvs_scratch
