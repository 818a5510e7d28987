#include "unsup_mvs/tools/args.h"

#include <CLI/CLI.hpp>

#include <algorithm>
#include <cstdlib>
#include <iostream>
#include <sstream>
#include <stdexcept>

namespace umvs {
namespace {

constexpr int kHelpColumn = 34;  // --help: where the descriptions start

bool is_number(const std::string& text) {
  if (text.empty()) return false;
  char* end = nullptr;
  std::strtod(text.c_str(), &end);
  return end == text.c_str() + text.size();
}

}  // namespace

Args::Args(std::string command, std::string description)
    : app_(std::make_unique<CLI::App>(std::move(description), "umvs " + command)) {
  app_->get_formatter()->column_width(kHelpColumn);
}
Args::~Args() = default;
Args::Args(Args&&) noexcept = default;
Args& Args::operator=(Args&&) noexcept = default;

Args& Args::option(const std::string& name, const std::string& def, const std::string& help) {
  CLI::Option* opt = app_->add_option("--" + name, values_[name], help)
                         ->expected(1)
                         ->allow_extra_args(false)  // one value per occurrence
                         ->multi_option_policy(CLI::MultiOptionPolicy::TakeLast);
  if (!def.empty()) opt->default_str(def);
  if (is_number(def)) opt->check(CLI::Validator(CLI::Number).description(""))->type_name("NUMBER");
  else opt->type_name("TEXT");
  defaults_[name] = def;
  order_.push_back(name);
  return *this;
}
Args& Args::option(const std::string& name, double def, const std::string& help) {
  std::ostringstream text;
  text << def;
  return option(name, text.str(), help);
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

bool Args::parse(int argc, char** argv) {
  std::vector<std::string> args(argv, argv + argc);
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
