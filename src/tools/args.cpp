#include "unsup_mvs/tools/args.h"

#include <iostream>
#include <sstream>
#include <stdexcept>

namespace umvs {

Args::Args(std::string command, std::string usage) : command_(std::move(command)), usage_(std::move(usage)) {}

Args& Args::option(const std::string& name, const std::string& def, const std::string& help) {
  specs_[name] = {def, help, false, false, false};
  order_.push_back(name);
  return *this;
}
Args& Args::option(const std::string& name, double def, const std::string& help) {
  std::ostringstream text;
  text << def;
  return option(name, text.str(), help);
}
Args& Args::flag(const std::string& name, const std::string& help) {
  specs_[name] = {"", help, true, false, false};
  order_.push_back(name);
  return *this;
}
Args& Args::required(const std::string& name, const std::string& help) {
  specs_[name] = {"", help, false, true, false};
  order_.push_back(name);
  return *this;
}
Args& Args::repeated(const std::string& name, const std::string& help) {
  specs_[name] = {"", help, false, false, true};
  order_.push_back(name);
  return *this;
}

bool Args::parse(int argc, char** argv) {
  for (int i = 0; i < argc; ++i) {
    std::string arg = argv[i];
    if (arg == "--help" || arg == "-h") {
      std::cout << usage();
      return false;
    }
    if (arg.rfind("--", 0) != 0) throw std::invalid_argument("unexpected argument '" + arg + "' (options start with --)");
    std::string name = arg.substr(2), value;
    const auto eq = name.find('=');
    const bool inline_value = eq != std::string::npos;
    if (inline_value) {
      value = name.substr(eq + 1);
      name = name.substr(0, eq);
    }
    auto it = specs_.find(name);
    if (it == specs_.end()) throw std::invalid_argument("unknown option --" + name + " (see umvs " + command_ + " --help)");
    if (it->second.is_flag) {
      values_[name] = {inline_value ? value : "1"};
      continue;
    }
    if (!inline_value) {
      if (i + 1 >= argc) throw std::invalid_argument("option --" + name + " needs a value");
      value = argv[++i];
    }
    if (it->second.is_repeated) values_[name].push_back(value);
    else values_[name] = {value};
  }
  for (const auto& s : specs_) {
    if (s.second.is_required && !values_.count(s.first)) throw std::invalid_argument("missing required option --" + s.first);
  }
  return true;
}

std::string Args::str(const std::string& name) const {
  auto v = values_.find(name);
  if (v != values_.end() && !v->second.empty()) return v->second.back();
  auto s = specs_.find(name);
  if (s == specs_.end()) throw std::logic_error("option --" + name + " was not declared");
  return s->second.default_value;
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

bool Args::given(const std::string& name) const { return values_.count(name) > 0; }

bool Args::on(const std::string& name) const {
  const std::string s = str(name);
  return !s.empty() && s != "0" && s != "false" && s != "no";
}

std::vector<std::string> Args::all(const std::string& name) const {
  std::vector<std::string> out;
  auto v = values_.find(name);
  std::vector<std::string> raw = v != values_.end() ? v->second : std::vector<std::string>{str(name)};
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

std::string Args::usage() const {
  std::ostringstream os;
  os << "usage: umvs " << command_ << " [options]\n" << usage_ << "\n\noptions:\n";
  for (const auto& name : order_) {
    const auto& s = specs_.at(name);
    std::string left = "  --" + name + (s.is_flag ? "" : " VALUE");
    os << left << std::string(left.size() < 28 ? 28 - left.size() : 1, ' ') << s.help;
    if (s.is_required) os << " (required)";
    else if (!s.is_flag && !s.default_value.empty()) os << " [default: " << s.default_value << "]";
    if (s.is_repeated) os << " (repeatable)";
    os << "\n";
  }
  return os.str();
}

}  // namespace umvs
