// A Config struct's settings, each declared once: its name, the field it sets, the range a live
// change may take and what it means. The one declaration drives every place a user meets the
// setting: the `umvs` option (the name with dashes), the node's ROS parameter and YAML key, the
// dynamic_reconfigure entry (checked against cfg/*.cfg by a test) and the reference table in the
// docs (settings_table()). The default is the field's initialiser: a default-made Config's value.
#pragma once

#include <sstream>
#include <string>
#include <variant>
#include <vector>

namespace umvs {

template <class Config>
struct Setting {
  using Field = std::variant<double Config::*, int Config::*>;

  std::string name;  // snake_case: ROS parameter, YAML key and dynamic_reconfigure name
  Field field;
  double min = 0.0;  // the range dynamic_reconfigure offers; Config::validate() has the last word
  double max = 0.0;
  std::string help;
  bool on_node = true;  // false: a `umvs` option only (not a parameter of the node, not live)
  std::vector<std::string> old_options = {};  // earlier `umvs` spellings, taken with a deprecation note

  // The `umvs` option: the name with dashes (min_agreeing_views -> min-agreeing-views).
  std::string option() const {
    std::string dashed = name;
    for (char& c : dashed) c = c == '_' ? '-' : c;
    return dashed;
  }
  bool is_integer() const { return std::holds_alternative<int Config::*>(field); }
  double value(const Config& config) const {
    return std::visit([&](auto member) { return static_cast<double>(config.*member); }, field);
  }
  // Calls f(config.*field) with the field's own type (double& or int&).
  template <class F>
  void visit(Config& config, F&& f) const {
    std::visit([&](auto member) { f(config.*member); }, field);
  }
};

// The shortest text of a number as the docs and --help show it (0.8, 1, 0.01, 2000000).
inline std::string setting_text(double v) {
  std::ostringstream out;
  out.precision(15);
  out << v;
  return out.str();
}

// The reference table of a Config's settings (Markdown), as docs/*.md hold it between
// `<!-- settings: NAME -->` and `<!-- end settings -->` (a test keeps them equal).
template <class Config>
std::string settings_table(const std::vector<Setting<Config>>& settings, const std::string& command) {
  const Config defaults{};
  std::string table = "| setting (ROS parameter, YAML, dynamic_reconfigure) | `umvs " + command +
                      "` option | default | live range | meaning |\n|---|---|---|---|---|\n";
  for (const auto& s : settings) {
    std::string option = "`--" + s.option() + "`";
    for (const auto& old : s.old_options) option += " (was `--" + old + "`)";
    const std::string range = s.on_node ? setting_text(s.min) + " .. " + setting_text(s.max) : "`umvs` only";
    table += "| `" + s.name + "` | " + option + " | " + setting_text(s.value(defaults)) + " | " + range + " | " +
             s.help + " |\n";
  }
  return table;
}

}  // namespace umvs
