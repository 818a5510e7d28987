// umvs: the unsup_mvs command line. Each subcommand lives in src/tools/cmd_*.cpp.
#include <c10/util/Exception.h>

#include <iostream>

#include "unsup_mvs/tools/args.h"
#include "unsup_mvs/tools/command.h"

namespace umvs {
std::map<std::string, CommandInfo>& command_table() {
  static std::map<std::string, CommandInfo> table;
  return table;
}
}  // namespace umvs

namespace {
void print_usage() {
  std::vector<std::pair<std::string, std::string>> commands;
  for (const auto& c : umvs::command_table()) commands.emplace_back(c.first, c.second.summary);
  std::cout << umvs::subcommands_help("umvs", "umvs: unsupervised multi-view stereo (MVSNet + robust photometric loss)", commands);
}
}  // namespace

int main(int argc, char** argv) {
  if (argc < 2 || std::string(argv[1]) == "--help" || std::string(argv[1]) == "-h" || std::string(argv[1]) == "help") {
    print_usage();
    return argc < 2 ? 2 : 0;
  }
  const auto& table = umvs::command_table();
  auto it = table.find(argv[1]);
  if (it == table.end()) {
    std::cerr << "umvs: unknown command '" << argv[1] << "'\n\n";
    print_usage();
    return 2;
  }
  try {
    return it->second.run(argc - 2, argv + 2);
  } catch (const std::invalid_argument& e) {
    std::cerr << "umvs " << argv[1] << ": error: " << e.what() << "\n";
    return 2;
  } catch (const c10::Error& e) {  // LibTorch's checks: the message, not its C++ backtrace
    std::cerr << "umvs " << argv[1] << ": error: " << e.what_without_backtrace() << "\n";
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "umvs " << argv[1] << ": error: " << e.what() << "\n";
    return 1;
  }
}
