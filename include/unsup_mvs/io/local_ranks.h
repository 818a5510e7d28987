// `umvs train --nproc K`: one distributed job of K ranks on this machine. The launcher starts K
// copies of a command with the torchrun variables (WORLD_SIZE, RANK, MASTER_ADDR=127.0.0.1,
// MASTER_PORT = a free port), relays rank 0's output, and fails as a whole: when one rank fails,
// the others are stopped and the failing rank's last lines are reported. No rank outlives the
// launcher (ChildProcess kills children whose parent died).
#pragma once

#include <iosfwd>
#include <string>
#include <vector>

namespace umvs {

struct LocalRanksResult {
  int exit_status = 0;     // 0 when every rank succeeded; else the first failing rank's status
  int failed_rank = -1;    // -1 when none failed
  std::string message;     // what went wrong, with the failing rank's last output lines
};

// argv[0] must be an absolute path. Rank 0's output goes to `out` as it comes; the other ranks'
// output is kept (last lines) for error reports. Blocks until all ranks ended.
LocalRanksResult run_local_ranks(const std::vector<std::string>& argv, int ranks, std::ostream& out);

// `umvs <command> ARGS` (argc, argv: ARGS) again as `ranks` local ranks of this executable
// (/proc/self/exe), without its --nproc option. Rank 0's output and the launcher's messages go to
// `log`, "all K ranks finished" to `out`. Returns the exit status: 0, the failing rank's (2: bad
// usage), or 1 when it was killed.
int rerun_as_local_ranks(const std::string& command, int argc, char** argv, int ranks, std::ostream& log,
                         std::ostream& out);

// A TCP port on 127.0.0.1 that was free a moment ago (bound to port 0 and released).
int free_local_port();

}  // namespace umvs
