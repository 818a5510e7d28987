// Helpers of the command-line tests (test_reliability_cli.cpp, test_bag_reliability_cli.cpp,
// test_bag_judge_audit.cpp): run the built `umvs` or a script, compare files before and after,
// write small synthetic scenes.
#pragma once

#include <sys/wait.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>

#include "test_util.h"
#include "unsup_mvs/io/run_folder.h"

namespace umvs::test {

struct Result {
  int status = -1;     // exit status (-1: killed or not run)
  std::string output;  // stdout and/or stderr (see run_umvs)
};

// A shell command line (ours, quoted where needed). `redirect` chooses what Result::output holds:
// stdout and stderr (default), only stdout ("2>/dev/null") or only stderr ("2>&1 >/dev/null").
inline Result run_shell(const std::string& command, const std::string& redirect = "2>&1") {
  Result r;
  const std::string cmd = command + " " + redirect;
  FILE* pipe = ::popen(cmd.c_str(), "r");
  if (!pipe) return r;
  char buf[4096];
  for (size_t n; (n = std::fread(buf, 1, sizeof(buf), pipe)) > 0;) r.output.append(buf, n);
  const int status = ::pclose(pipe);
  r.status = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

// `umvs ARGS` through the shell, as run_shell.
inline Result run_umvs(const std::string& args, const std::string& redirect = "2>&1") {
  return run_shell(umvs_binary() + " " + args, redirect);
}

// The options recorded in run folder `out` (its run_config.json).
inline RunOptions recorded(const std::string& out) { return read_run_record(out).value().options; }

inline bool contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

inline std::string file_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

inline void write_bytes(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary);
  out << bytes;
}

// Every file under `dir` with its content, to show that a refused call changed nothing.
inline std::map<std::string, std::string> snapshot(const std::string& dir) {
  std::map<std::string, std::string> files;
  for (const auto& e : std::filesystem::recursive_directory_iterator(dir)) {
    if (e.is_regular_file()) files[e.path().string()] = file_bytes(e.path().string());
  }
  return files;
}

// The smallest training run the command-line tests use (add --data, --steps, --out).
inline const std::string kTrainFlags =
    " --width 96 --height 64 --num-depth 8 --views-loss 3 --top-k 2 --threads 1 --save-every 2";

// A small synthetic room as an MVSNet folder (exact depth in depth_gt/), written once per name.
inline std::string scene(const std::string& name, int width = 96, int height = 64, int views = 5) {
  return write_room(name, 2, true, width, height, views);
}

}  // namespace umvs::test
