// The options of one umvs subcommand, declared once and parsed by CLI11: "--name value",
// "--name=value" and "--flag". CLI11 writes --help (with the defaults) from the declarations and
// refuses unknown options, missing values and non-numbers where the default is a number, naming
// the option.
#pragma once

#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <utility>
#include <vector>

namespace CLI {
class App;
}

namespace umvs {

class Args {
 public:
  // `description` is printed by --help above the options.
  Args(std::string command, std::string description);
  ~Args();
  Args(Args&&) noexcept;
  Args& operator=(Args&&) noexcept;

  // Declare options before parse(). `help` appears in the usage text. An option whose default
  // is a number only takes numbers.
  Args& option(const std::string& name, const std::string& default_value, const std::string& help);
  // A numeric default, usually a Config struct's own field, so that the command line and the
  // library cannot disagree on it.
  Args& option(const std::string& name, double default_value, const std::string& help);
  // An integer default: the option only takes integers ("--threads abc" is refused as such).
  Args& option(const std::string& name, int default_value, const std::string& help);
  Args& flag(const std::string& name, const std::string& help);
  Args& required(const std::string& name, const std::string& help);
  // An option that may be given several times (e.g. --bag a.bag --bag b.bag).
  Args& repeated(const std::string& name, const std::string& help);

  // Options bound to a field of a config struct: the field's value is the default (--help shows
  // it), and parse() writes a given value into the field, so that the struct's initialiser is the
  // option's only default. An int option takes integers only; a bool option 0 or 1; an optional
  // int has no default; a list is comma-separated (bind_repeated: also repeatable).
  Args& bind(const std::string& name, std::string* field, const std::string& help);
  Args& bind(const std::string& name, double* field, const std::string& help);
  Args& bind(const std::string& name, int* field, const std::string& help);
  Args& bind(const std::string& name, bool* field, const std::string& help);
  Args& bind(const std::string& name, std::optional<int>* field, const std::string& help);
  Args& bind(const std::string& name, std::vector<std::string>* field, const std::string& help);
  Args& bind(const std::string& name, std::vector<double>* field, const std::string& help);  // comma-separated
  Args& bind(const std::string& name, std::vector<int>* field, const std::string& help);     // comma-separated
  Args& bind_repeated(const std::string& name, std::vector<std::string>* field, const std::string& help);
  Args& flag(const std::string& name, bool* field, const std::string& help);
  // An earlier spelling of a declared option: still taken, as `name`, with a note on stderr that
  // it is deprecated (kept for one release after a rename).
  Args& deprecated(const std::string& old_name, const std::string& name);

  // Returns false when --help was given (usage already printed). Throws std::invalid_argument
  // with a message naming the offending option otherwise; an unknown option is reported first
  // (with the declared one it most resembles), before any missing one.
  bool parse(int argc, char** argv);

  std::string str(const std::string& name) const;
  int integer(const std::string& name) const;
  double real(const std::string& name) const;
  bool given(const std::string& name) const;
  std::set<std::string> given_names() const;  // the options on the command line
  bool on(const std::string& name) const;  // for flags
  std::vector<std::string> all(const std::string& name) const;  // repeated or comma-separated
  std::vector<int> integers(const std::string& name) const;     // comma-separated ints
  std::vector<double> reals(const std::string& name) const;     // comma-separated finite numbers

  std::string usage() const;  // CLI11's help text
  const std::vector<std::string>& names() const { return order_; }  // declared options, in order

 private:
  std::unique_ptr<CLI::App> app_;
  std::vector<std::string> order_;
  enum class Kind { kText, kNumber, kInteger };
  Args& declare(const std::string& name, const std::string& default_value, const std::string& help, Kind kind);
  void check_known_options(const std::vector<std::string>& args) const;
  std::map<std::string, std::string> defaults_;
  std::map<std::string, std::string> renamed_;  // old spelling -> declared name
  // CLI11 writes into these (std::map keeps their addresses while options are added).
  std::map<std::string, std::vector<std::string>> values_;
  std::map<std::string, bool> flags_;
  // After parsing: given values into the bound fields (handed the Args, which may have moved).
  std::vector<std::function<void(const Args&)>> write_bound_;
};

// --help of a program or command whose first argument picks what runs (umvs <command>,
// umvs eval depth|cloud): CLI11's help listing each (name, summary) as a subcommand.
std::string subcommands_help(const std::string& program, const std::string& description,
                             const std::vector<std::pair<std::string, std::string>>& subcommands);

}  // namespace umvs
