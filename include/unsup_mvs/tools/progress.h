// A one-line progress bar with rate and ETA on stderr ("[=====>    ] 12/40  3.1 s/it  ETA 1m27s").
// Redraws in place on a terminal; prints a plain line every `log_every` items otherwise (logs, CI).
#pragma once

#include <chrono>
#include <string>

namespace umvs {

class Progress {
 public:
  Progress(std::string label, int64_t total, int64_t log_every = 0);
  // Advance to `done` items; `extra` is appended to the line (e.g. loss terms).
  void update(int64_t done, const std::string& extra = "");
  void finish(const std::string& extra = "");
  double elapsed_seconds() const;

 private:
  std::string label_;
  int64_t total_, log_every_, last_logged_ = -1;
  bool tty_;
  std::chrono::steady_clock::time_point start_;
};

std::string format_duration(double seconds);

}  // namespace umvs
