#include "unsup_mvs/io/child_process.h"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <stdexcept>
#include <thread>

namespace umvs {

ChildProcess::~ChildProcess() {
  stop(1.0);
  if (out_fd_ >= 0) ::close(out_fd_);
}

void ChildProcess::start(const std::vector<std::string>& argv) {
  if (pid_ > 0 && !exited_) throw std::runtime_error("a child process is already running");
  if (argv.empty() || argv[0].empty() || argv[0][0] != '/') {
    throw std::runtime_error("program must be given by absolute path, got '" + (argv.empty() ? "" : argv[0]) + "'");
  }
  if (::access(argv[0].c_str(), X_OK) != 0) throw std::runtime_error("cannot execute '" + argv[0] + "': " + std::strerror(errno));
  int fds[2];
  if (::pipe2(fds, O_CLOEXEC) != 0) throw std::runtime_error(std::string("pipe: ") + std::strerror(errno));
  std::vector<char*> args;
  for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  const pid_t parent = ::getpid();
  const pid_t pid = ::fork();
  if (pid < 0) {
    ::close(fds[0]);
    ::close(fds[1]);
    throw std::runtime_error(std::string("fork: ") + std::strerror(errno));
  }
  if (pid == 0) {
    // Child: own process group (so a stop reaches its threads' children too), output to the pipe.
    ::setpgid(0, 0);
    // Die with the parent: a SIGKILLed node must not leave its child writing into its folders.
    // (getppid() check: the parent may have died before prctl took effect.)
    ::prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (::getppid() != parent) ::_exit(127);
    ::dup2(fds[1], STDOUT_FILENO);
    ::dup2(fds[1], STDERR_FILENO);
    ::execv(args[0], args.data());
    const char msg[] = "exec failed\n";
    (void)!::write(STDERR_FILENO, msg, sizeof(msg) - 1);
    ::_exit(127);
  }
  ::setpgid(pid, pid);  // also here: whichever of parent and child runs first sets the group
  ::close(fds[1]);
  if (out_fd_ >= 0) ::close(out_fd_);
  out_fd_ = fds[0];
  ::fcntl(out_fd_, F_SETFL, ::fcntl(out_fd_, F_GETFL) | O_NONBLOCK);
  pid_ = pid;
  exited_ = false;
  status_ = 0;
  partial_.clear();
}

void ChildProcess::reap(bool block) {
  if (pid_ <= 0 || exited_) return;
  int st = 0;
  const pid_t r = ::waitpid(pid_, &st, block ? 0 : WNOHANG);
  if (r == pid_) {
    exited_ = true;
    status_ = WIFEXITED(st) ? WEXITSTATUS(st) : (WIFSIGNALED(st) ? -WTERMSIG(st) : -1);
  }
}

bool ChildProcess::running() {
  reap(false);
  return pid_ > 0 && !exited_;
}

bool ChildProcess::poll(const std::function<void(const std::string&)>& on_line) {
  if (out_fd_ < 0) return false;
  char buf[4096];
  bool eof = false;
  for (;;) {
    const ssize_t n = ::read(out_fd_, buf, sizeof(buf));
    if (n > 0) {
      partial_.append(buf, static_cast<size_t>(n));
      continue;
    }
    if (n == 0) eof = true;
    else if (errno == EINTR) continue;
    break;  // EAGAIN: nothing more for now
  }
  size_t start = 0;
  for (size_t i = 0; i < partial_.size(); ++i) {
    if (partial_[i] == '\n' || partial_[i] == '\r') {
      if (i > start) on_line(partial_.substr(start, i - start));
      start = i + 1;
    }
  }
  partial_.erase(0, start);
  if (!eof) return true;
  if (!partial_.empty()) on_line(partial_);
  partial_.clear();
  ::close(out_fd_);
  out_fd_ = -1;
  reap(true);
  return false;
}

void ChildProcess::stop(double grace_seconds) {
  if (!running()) return;
  ::kill(-pid_, SIGTERM);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(grace_seconds);
  while (std::chrono::steady_clock::now() < deadline) {
    if (!running()) return;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  ::kill(-pid_, SIGKILL);
  reap(true);
}

}  // namespace umvs
