// Shared pieces of `umvs bench` cases.
#pragma once

#include <vector>

namespace umvs {

struct BenchStats {
  int runs = 0;
  double median = 0, min = 0, max = 0;  // seconds
};
BenchStats summarize(std::vector<double> seconds);
double peak_rss_mib();  // peak resident memory of this process (VmHWM)
long minor_page_faults();  // of this process so far (getrusage)

}  // namespace umvs
