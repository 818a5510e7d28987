#include "unsup_mvs/tools/progress.h"

#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <iostream>

namespace umvs {

std::string format_duration(double s) {
  char buf[32];
  if (!std::isfinite(s) || s < 0) return "?";
  if (s < 60) std::snprintf(buf, sizeof(buf), "%.1fs", s);
  else if (s < 3600) std::snprintf(buf, sizeof(buf), "%dm%02ds", static_cast<int>(s) / 60, static_cast<int>(s) % 60);
  else std::snprintf(buf, sizeof(buf), "%dh%02dm", static_cast<int>(s) / 3600, (static_cast<int>(s) % 3600) / 60);
  return buf;
}

Progress::Progress(std::string label, int64_t total, int64_t log_every)
    : label_(std::move(label)), total_(total), tty_(::isatty(STDERR_FILENO)), start_(std::chrono::steady_clock::now()) {
  log_every_ = log_every > 0 ? log_every : std::max<int64_t>(1, total / 20);
}

double Progress::elapsed_seconds() const {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
}

void Progress::update(int64_t done, const std::string& extra) {
  const bool last = done >= total_;
  // Off a terminal: one line every log_every items and one for the end, never the same item twice.
  if (!tty_ && (done == last_logged_ || (!last && done - last_logged_ < log_every_ && last_logged_ >= 0))) return;
  last_logged_ = done;
  const double t = elapsed_seconds();
  const double per_item = done > 0 ? t / done : NAN;
  const double eta = done > 0 ? per_item * (total_ - done) : NAN;
  const int width = 24;
  const int filled = total_ > 0 ? static_cast<int>(width * std::min<int64_t>(done, total_) / total_) : 0;
  std::string bar(filled, '=');
  if (filled < width) bar += '>' + std::string(width - filled - 1, ' ');
  char head[160];
  std::snprintf(head, sizeof(head), "%s [%s] %lld/%lld  %s/it  ETA %s", label_.c_str(), bar.c_str(),
                static_cast<long long>(done), static_cast<long long>(total_), format_duration(per_item).c_str(),
                format_duration(eta).c_str());
  std::cerr << (tty_ ? "\r\033[K" : "") << head << (extra.empty() ? "" : "  ") << extra << (tty_ ? "" : "\n") << std::flush;
}

void Progress::finish(const std::string& extra) {
  update(total_, extra);
  if (tty_) std::cerr << "\n";
  std::cerr << label_ << ": done in " << format_duration(elapsed_seconds()) << "\n";
}

}  // namespace umvs
