// Subcommands of the `umvs` tool register themselves:
//   UMVS_COMMAND(infer, "depth maps for an MVSNet-format folder") { ... return 0; }
// defines `int umvs_cmd_infer(int argc, char** argv)` (argv holds the arguments after the
// subcommand name) and adds it to the table that `umvs --help` lists.
#pragma once

#include <functional>
#include <map>
#include <string>

namespace umvs {

struct CommandInfo {
  std::string summary;
  std::function<int(int, char**)> run;
};
std::map<std::string, CommandInfo>& command_table();

struct CommandRegistrar {
  CommandRegistrar(const std::string& name, const std::string& summary, std::function<int(int, char**)> run) {
    command_table()[name] = {summary, std::move(run)};
  }
};

}  // namespace umvs

#define UMVS_COMMAND(name, summary)                                                          \
  int umvs_cmd_##name(int argc, char** argv);                                                \
  static ::umvs::CommandRegistrar umvs_registrar_##name(#name, summary, &umvs_cmd_##name);   \
  int umvs_cmd_##name(int argc, char** argv)
