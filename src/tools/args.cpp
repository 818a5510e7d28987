#include "unsup_mvs/tools/args.h"

#include <CLI/CLI.hpp>

#include <algorithm>
#include <cerrno>
#include <climits>
#include <cmath>
#include <cstdlib>
#include <iostream>
#include <sstream>
#include <stdexcept>

#include "unsup_mvs/io/run_folder.h"

namespace umvs {
namespace {

constexpr int kHelpColumn = 34;  // --help: where the descriptions start

bool is_number(const std::string& text) {
  if (text.empty()) return false;
  char* end = nullptr;
  std::strtod(text.c_str(), &end);
  return end == text.c_str() + text.size();
}

bool is_integer(const std::string& text) {
  if (text.empty()) return false;
  char* end = nullptr;
  errno = 0;
  const long v = std::strtol(text.c_str(), &end, 10);
  return end == text.c_str() + text.size() && errno == 0 && v >= INT_MIN && v <= INT_MAX;
}

// The shortest text that reads back as `v` (--help shows 0.001, not 0.0010000000000000000208).
std::string number_text(double v) { return option_text(nlohmann::json(v)); }

// Levenshtein distance, for "did you mean".
size_t edit_distance(const std::string& a, const std::string& b) {
  std::vector<size_t> row(b.size() + 1);
  for (size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (size_t i = 1; i <= a.size(); ++i) {
    size_t diagonal = row[0];
    row[0] = i;
    for (size_t j = 1; j <= b.size(); ++j) {
      const size_t above = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diagonal + (a[i - 1] == b[j - 1] ? 0 : 1)});
      diagonal = above;
    }
  }
  return row[b.size()];
}

}  // namespace

Args::Args(std::string command, std::string description)
    : app_(std::make_unique<CLI::App>(std::move(description), "umvs " + command)) {
  app_->get_formatter()->column_width(kHelpColumn);
}
Args::~Args() = default;
Args::Args(Args&&) noexcept = default;
Args& Args::operator=(Args&&) noexcept = default;

Args& Args::declare(const std::string& name, const std::string& def, const std::string& help, Kind kind) {
  CLI::Option* opt = app_->add_option("--" + name, values_[name], help)
                         ->expected(1)
                         ->allow_extra_args(false)  // one value per occurrence
                         ->multi_option_policy(CLI::MultiOptionPolicy::TakeLast);
  if (!def.empty()) opt->default_str(def);
  if (kind == Kind::kInteger) {
    opt->check(CLI::Validator(
                   [](std::string& v) { return is_integer(v) ? std::string() : "needs an integer, got '" + v + "'"; }, ""))
        ->type_name("INT");
  } else if (kind == Kind::kNumber) {
    opt->check(CLI::Validator(
                   [](std::string& v) { return is_number(v) ? std::string() : "needs a number, got '" + v + "'"; }, ""))
        ->type_name("NUMBER");
  } else {
    opt->type_name("TEXT");
  }
  defaults_[name] = def;
  order_.push_back(name);
  return *this;
}
Args& Args::option(const std::string& name, const std::string& def, const std::string& help) {
  return declare(name, def, help, is_number(def) ? Kind::kNumber : Kind::kText);
}
Args& Args::option(const std::string& name, double def, const std::string& help) {
  std::ostringstream text;
  text << def;
  return declare(name, text.str(), help, Kind::kNumber);
}
Args& Args::option(const std::string& name, int def, const std::string& help) {
  return declare(name, std::to_string(def), help, Kind::kInteger);
}
Args& Args::flag(const std::string& name, const std::string& help) {
  app_->add_flag("--" + name, flags_[name], help);
  defaults_[name] = "";
  order_.push_back(name);
  return *this;
}
Args& Args::required(const std::string& name, const std::string& help) {
  option(name, "", help);
  app_->get_option("--" + name)->required();
  return *this;
}
Args& Args::repeated(const std::string& name, const std::string& help) {
  option(name, "", help);
  app_->get_option("--" + name)->multi_option_policy(CLI::MultiOptionPolicy::TakeAll)->description(help + " (repeatable)");
  return *this;
}

Args& Args::bind(const std::string& name, std::string* field, const std::string& help) {
  declare(name, *field, help, Kind::kText);
  write_bound_.push_back([name, field](const Args& a) {
    if (a.given(name)) *field = a.str(name);
  });
  return *this;
}
Args& Args::bind(const std::string& name, double* field, const std::string& help) {
  declare(name, number_text(*field), help, Kind::kNumber);
  write_bound_.push_back([name, field](const Args& a) {
    if (a.given(name)) *field = a.real(name);
  });
  return *this;
}
Args& Args::bind(const std::string& name, int* field, const std::string& help) {
  option(name, *field, help);
  write_bound_.push_back([name, field](const Args& a) {
    if (a.given(name)) *field = a.integer(name);
  });
  return *this;
}
Args& Args::bind(const std::string& name, bool* field, const std::string& help) {
  option(name, *field ? 1 : 0, help);
  write_bound_.push_back([name, field](const Args& a) {
    if (!a.given(name)) return;
    const std::string v = a.str(name);
    if (v != "0" && v != "1") throw std::invalid_argument("--" + name + " must be 0 or 1, got '" + v + "'");
    *field = v == "1";
  });
  return *this;
}
Args& Args::bind(const std::string& name, std::optional<int>* field, const std::string& help) {
  declare(name, field->has_value() ? std::to_string(**field) : "", help, Kind::kInteger);
  write_bound_.push_back([name, field](const Args& a) {
    if (a.given(name)) *field = a.integer(name);
  });
  return *this;
}
Args& Args::bind(const std::string& name, std::vector<std::string>* field, const std::string& help) {
  std::string joined;
  for (const auto& item : *field) joined += (joined.empty() ? "" : ",") + item;
  declare(name, joined, help, Kind::kText);
  write_bound_.push_back([name, field](const Args& a) {
    if (a.given(name)) *field = a.all(name);
  });
  return *this;
}
Args& Args::bind(const std::string& name, std::vector<double>* field, const std::string& help) {
  std::string joined;
  for (double v : *field) joined += (joined.empty() ? "" : ",") + number_text(v);
  declare(name, joined, help, Kind::kText);
  write_bound_.push_back([name, field](const Args& a) {
    if (a.given(name)) *field = a.reals(name);
  });
  return *this;
}
Args& Args::bind(const std::string& name, std::vector<int>* field, const std::string& help) {
  std::string joined;
  for (int v : *field) joined += (joined.empty() ? "" : ",") + std::to_string(v);
  declare(name, joined, help, Kind::kText);
  write_bound_.push_back([name, field](const Args& a) {
    if (a.given(name)) *field = a.integers(name);
  });
  return *this;
}
Args& Args::bind_repeated(const std::string& name, std::vector<std::string>* field, const std::string& help) {
  bind(name, field, help);
  app_->get_option("--" + name)->multi_option_policy(CLI::MultiOptionPolicy::TakeAll)->description(help + " (repeatable)");
  return *this;
}
Args& Args::flag(const std::string& name, bool* field, const std::string& help) {
  flag(name, help);
  write_bound_.push_back([name, field](const Args& a) {
    if (a.given(name)) *field = a.on(name);
  });
  return *this;
}

Args& Args::deprecated(const std::string& old_name, const std::string& name) {
  if (!defaults_.count(name)) throw std::logic_error("option --" + name + " was not declared");
  renamed_[old_name] = name;
  return *this;
}

void Args::check_known_options(const std::vector<std::string>& args) const {
  for (const auto& a : args) {
    if (a.size() < 3 || a.compare(0, 2, "--") != 0) continue;
    const std::string name = a.substr(2, a.find('=') == std::string::npos ? std::string::npos : a.find('=') - 2);
    if (name == "help" || defaults_.count(name)) continue;
    std::string closest;
    size_t best = 3;  // suggest only names at most two edits away
    for (const auto& known : order_) {
      const size_t d = edit_distance(name, known);
      if (d < best) best = d, closest = known;
    }
    throw std::invalid_argument("unknown option --" + name + (closest.empty() ? "" : " (did you mean --" + closest + "?)") +
                                " (see " + app_->get_name() + " --help)");
  }
}

bool Args::parse(int argc, char** argv) {
  std::vector<std::string> args(argv, argv + argc);
  for (auto& a : args) {  // earlier spellings: "--old" or "--old=value"
    if (a.compare(0, 2, "--") != 0) continue;
    const size_t end = a.find('=');
    const auto renamed = renamed_.find(a.substr(2, end == std::string::npos ? std::string::npos : end - 2));
    if (renamed == renamed_.end()) continue;
    std::cerr << app_->get_name() << ": --" << renamed->first << " is deprecated and will be removed in the next release; "
              << "use --" << renamed->second << "\n";
    a = "--" + renamed->second + (end == std::string::npos ? "" : a.substr(end));
  }
  check_known_options(args);
  std::reverse(args.begin(), args.end());  // CLI11 takes them last first
  try {
    app_->parse(args);
  } catch (const CLI::CallForHelp&) {
    std::cout << usage();
    return false;
  } catch (const CLI::ParseError& e) {
    throw std::invalid_argument(std::string(e.what()) + " (see " + app_->get_name() + " --help)");
  }
  for (const auto& f : flags_) {
    if (app_->get_option("--" + f.first)->count() > 0) values_[f.first] = {f.second ? "1" : "0"};
  }
  for (const auto& write : write_bound_) write(*this);
  return true;
}

std::string Args::str(const std::string& name) const {
  auto v = values_.find(name);
  if (v != values_.end() && !v->second.empty()) return v->second.back();
  auto d = defaults_.find(name);
  if (d == defaults_.end()) throw std::logic_error("option --" + name + " was not declared");
  return d->second;
}

int Args::integer(const std::string& name) const {
  const std::string s = str(name);
  try {
    size_t used = 0;
    const int v = std::stoi(s, &used);
    if (used == s.size()) return v;
  } catch (const std::exception&) {
  }
  throw std::invalid_argument("option --" + name + " needs an integer, got '" + s + "'");
}

double Args::real(const std::string& name) const {
  const std::string s = str(name);
  try {
    size_t used = 0;
    const double v = std::stod(s, &used);
    if (used == s.size()) return v;
  } catch (const std::exception&) {
  }
  throw std::invalid_argument("option --" + name + " needs a number, got '" + s + "'");
}

bool Args::given(const std::string& name) const {
  auto v = values_.find(name);
  return v != values_.end() && !v->second.empty();
}

std::set<std::string> Args::given_names() const {
  std::set<std::string> names;
  for (const auto& name : order_) {
    if (given(name)) names.insert(name);
  }
  return names;
}

bool Args::on(const std::string& name) const {
  const std::string s = str(name);
  return !s.empty() && s != "0" && s != "false" && s != "no";
}

std::vector<std::string> Args::all(const std::string& name) const {
  std::vector<std::string> out;
  auto v = values_.find(name);
  std::vector<std::string> raw = given(name) ? v->second : std::vector<std::string>{str(name)};
  for (const auto& item : raw) {
    std::stringstream ss(item);
    for (std::string part; std::getline(ss, part, ',');) {
      if (!part.empty()) out.push_back(part);
    }
  }
  return out;
}

std::vector<double> Args::reals(const std::string& name) const {
  std::vector<double> out;
  for (const auto& s : all(name)) {
    char* end = nullptr;
    const double v = std::strtod(s.c_str(), &end);
    if (end != s.c_str() + s.size() || !std::isfinite(v)) {
      throw std::invalid_argument("option --" + name + " needs comma-separated numbers, got '" + s + "'");
    }
    out.push_back(v);
  }
  return out;
}

std::vector<int> Args::integers(const std::string& name) const {
  std::vector<int> out;
  for (const auto& s : all(name)) {
    try {
      size_t used = 0;
      out.push_back(std::stoi(s, &used));
      if (used != s.size()) throw std::invalid_argument(s);
    } catch (const std::exception&) {
      throw std::invalid_argument("option --" + name + " needs comma-separated integers, got '" + s + "'");
    }
  }
  return out;
}

std::string Args::usage() const { return app_->help(); }

std::string subcommands_help(const std::string& program, const std::string& description,
                             const std::vector<std::pair<std::string, std::string>>& subcommands) {
  CLI::App app(description, program);
  app.get_formatter()->column_width(kHelpColumn);
  app.require_subcommand(1);
  for (const auto& s : subcommands) app.add_subcommand(s.first, s.second);
  app.footer("(" + program + " <subcommand> --help for its options)");
  return app.help();
}

}  // namespace umvs
