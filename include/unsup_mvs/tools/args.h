// A small, strict command-line parser for the umvs subcommands: "--name value" and "--flag".
// Unknown flags, missing values and unparsable numbers are errors that name the flag.
#pragma once

#include <map>
#include <string>
#include <vector>

namespace umvs {

class Args {
 public:
  // `usage` is printed by --help and after errors.
  Args(std::string command, std::string usage);

  // Declare options before parse(). `help` appears in the usage text.
  Args& option(const std::string& name, const std::string& default_value, const std::string& help);
  // A numeric default, usually a Config struct's own field, so that the command line and the
  // library cannot disagree on it.
  Args& option(const std::string& name, double default_value, const std::string& help);
  Args& flag(const std::string& name, const std::string& help);
  Args& required(const std::string& name, const std::string& help);
  // An option that may be given several times (e.g. --bag a.bag --bag b.bag).
  Args& repeated(const std::string& name, const std::string& help);

  // Returns false when --help was given (usage already printed). Throws std::invalid_argument
  // with a message naming the offending flag otherwise.
  bool parse(int argc, char** argv);

  std::string str(const std::string& name) const;
  int integer(const std::string& name) const;
  double real(const std::string& name) const;
  bool given(const std::string& name) const;
  bool on(const std::string& name) const;  // for flags
  std::vector<std::string> all(const std::string& name) const;  // repeated or comma-separated
  std::vector<int> integers(const std::string& name) const;     // comma-separated ints

  std::string usage() const;
  const std::vector<std::string>& names() const { return order_; }  // declared options, in order

 private:
  struct Spec {
    std::string default_value, help;
    bool is_flag = false, is_required = false, is_repeated = false;
  };
  std::string command_, usage_;
  std::vector<std::string> order_;
  std::map<std::string, Spec> specs_;
  std::map<std::string, std::vector<std::string>> values_;
};

}  // namespace umvs
