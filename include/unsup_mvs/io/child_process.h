// Runs a program as a child process from an argument list (execv: never through a shell), reads
// its standard output and error line by line without blocking, and stops it on request. Used by
// the trainer node to run `umvs train` so that a crash of training never touches the node.
#pragma once

#include <sys/types.h>

#include <functional>
#include <string>
#include <vector>

namespace umvs {

class ChildProcess {
 public:
  ChildProcess() = default;
  ~ChildProcess();  // kills a still-running child and reaps it
  ChildProcess(const ChildProcess&) = delete;
  ChildProcess& operator=(const ChildProcess&) = delete;

  // argv[0] must be an absolute path to an executable. Throws std::runtime_error naming the
  // program when it cannot be started. stdout and stderr are merged into one stream. The child
  // is SIGKILLed when the thread that started it ends (PR_SET_PDEATHSIG), so it never outlives a
  // killed parent: start it from a thread that lives as long as the process (e.g. ROS callbacks).
  void start(const std::vector<std::string>& argv);

  // Reads what the child printed since the last call and hands every complete line to `on_line`
  // (without the newline; '\r'-separated progress redraws count as lines too). Returns false once
  // the child has exited and everything it printed was delivered.
  bool poll(const std::function<void(const std::string&)>& on_line);

  // SIGTERM, then SIGKILL after `grace_seconds` if it is still alive. Safe to call any time.
  void stop(double grace_seconds = 3.0);

  bool running();
  pid_t pid() const { return pid_; }
  // Valid once poll() returned false or stop() returned: the exit code, or -signal when killed.
  int exit_status() const { return status_; }

 private:
  void reap(bool block);
  pid_t pid_ = -1;
  int out_fd_ = -1;
  int status_ = 0;
  bool exited_ = false;
  std::string partial_;
};

}  // namespace umvs
