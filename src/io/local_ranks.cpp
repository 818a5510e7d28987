#include "unsup_mvs/io/local_ranks.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <deque>
#include <filesystem>
#include <memory>
#include <ostream>
#include <stdexcept>
#include <thread>

#include "unsup_mvs/io/child_process.h"

namespace umvs {

int free_local_port() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  if (fd < 0) throw std::runtime_error("cannot open a socket to find a free port");
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  addr.sin_port = 0;
  socklen_t len = sizeof(addr);
  const bool ok = ::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) == 0 &&
                  ::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len) == 0;
  ::close(fd);
  if (!ok) throw std::runtime_error("cannot find a free TCP port on 127.0.0.1");
  return ntohs(addr.sin_port);
}

LocalRanksResult run_local_ranks(const std::vector<std::string>& argv, int ranks, std::ostream& out) {
  if (ranks < 1) throw std::invalid_argument("the number of local ranks must be >= 1, got " + std::to_string(ranks));
  const int port = free_local_port();
  std::vector<std::unique_ptr<ChildProcess>> children;
  // The children inherit the environment at start: set the job's variables around each start.
  ::setenv("WORLD_SIZE", std::to_string(ranks).c_str(), 1);
  ::setenv("MASTER_ADDR", "127.0.0.1", 1);
  ::setenv("MASTER_PORT", std::to_string(port).c_str(), 1);
  for (int r = 0; r < ranks; ++r) {
    ::setenv("RANK", std::to_string(r).c_str(), 1);
    children.push_back(std::make_unique<ChildProcess>());
    children.back()->start(argv);
  }
  for (const char* name : {"WORLD_SIZE", "RANK", "MASTER_ADDR", "MASTER_PORT"}) ::unsetenv(name);

  constexpr size_t kKeptLines = 5;
  std::vector<std::deque<std::string>> last_lines(ranks);
  std::vector<bool> alive(ranks, true);
  LocalRanksResult result;
  int running = ranks;
  while (running > 0) {
    bool quiet = true;
    for (int r = 0; r < ranks; ++r) {
      if (!alive[r]) continue;
      const bool still = children[r]->poll([&](const std::string& line) {
        quiet = false;
        if (r == 0) out << line << "\n" << std::flush;
        last_lines[r].push_back(line);
        if (last_lines[r].size() > kKeptLines) last_lines[r].pop_front();
      });
      if (still) continue;
      alive[r] = false;
      --running;
      const int status = children[r]->exit_status();
      if (status != 0 && result.failed_rank < 0) {
        result.failed_rank = r;
        result.exit_status = status;
        std::string tail;
        for (const auto& l : last_lines[r]) tail += "\n  " + l;
        result.message = "rank " + std::to_string(r) + " of " + std::to_string(ranks) +
                         (status < 0 ? " was killed by signal " + std::to_string(-status)
                                     : " exited with status " + std::to_string(status)) +
                         "; the other ranks were stopped. Its last output:" + tail;
        // The job cannot go on without it: stop the others now rather than at their timeout.
        for (int o = 0; o < ranks; ++o) {
          if (alive[o]) children[o]->stop(2.0);
        }
      }
    }
    if (quiet && running > 0) std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return result;
}

int rerun_as_local_ranks(const std::string& command, int argc, char** argv, int ranks, std::ostream& log,
                         std::ostream& out) {
  std::error_code ec;
  const std::string self = std::filesystem::read_symlink("/proc/self/exe", ec).string();
  if (ec) throw std::runtime_error("--nproc: cannot find this program (/proc/self/exe): " + ec.message());
  std::vector<std::string> child = {self, command};
  for (int i = 0; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--nproc") {
      ++i;  // and its value
      continue;
    }
    if (arg.rfind("--nproc=", 0) == 0) continue;
    child.push_back(arg);
  }
  log << "starting " << ranks << " ranks on this machine (rank 0's output follows)\n";
  const LocalRanksResult result = run_local_ranks(child, ranks, log);
  if (result.failed_rank >= 0) {  // the failing rank's exit status (2: bad usage), 1 when it was killed
    log << "umvs " << command << ": error: " << result.message << "\n";
    return result.exit_status > 0 ? result.exit_status : 1;
  }
  out << "all " << ranks << " ranks finished\n";
  return 0;
}

}  // namespace umvs
