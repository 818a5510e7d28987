#include "unsup_mvs/io/run_folder.h"

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <stdexcept>

#include "unsup_mvs/io/atomic_file.h"
#include "unsup_mvs/io/input_limits.h"

namespace umvs {

namespace fs = std::filesystem;

const std::vector<std::string>& run_files() {
  static const std::vector<std::string> files = {"last.pt",       "best.pt",        "blended.pt",
                                                 "round_start.pt", "anchor.pt",      "train_log.csv",
                                                 "loss_curve.png", kRunConfigFile,   kLegacyRunConfigFile};
  return files;
}

std::string option_text(const nlohmann::json& value) {
  if (value.is_string()) return value.get<std::string>();
  if (value.is_boolean()) return value.get<bool>() ? "1" : "0";
  if (value.is_number_float()) {  // the shortest text that reads back as the value
    const double v = value.get<double>();
    char text[32];
    for (int digits = 6; digits <= 17; ++digits) {
      std::snprintf(text, sizeof(text), "%.*g", digits, v);
      if (std::strtod(text, nullptr) == v) break;
    }
    return text;
  }
  if (value.is_array()) {
    std::string joined;
    for (const auto& item : value) joined += (joined.empty() ? "" : ",") + option_text(item);
    return joined;
  }
  return value.dump();
}

std::string run_options_difference(const RunOptions& stored, const RunOptions& current,
                                   const std::vector<std::string>& may_change) {
  std::set<std::string> names;
  for (const auto& entry : stored.items()) names.insert(entry.key());
  for (const auto& entry : current.items()) names.insert(entry.key());
  // Every difference, not only the first: one refusal tells the whole resume command.
  std::string differences;
  for (const std::string& name : names) {
    if (std::find(may_change.begin(), may_change.end(), name) != may_change.end()) continue;
    const auto a = stored.find(name), b = current.find(name);
    const bool has_a = a != stored.end(), has_b = b != current.end();
    if (has_a && has_b && *a == *b) continue;  // (numbers compare by value: 1 == 1.0)
    const std::string was = has_a ? "'" + option_text(*a) + "'" : "(not set)";
    const std::string now = has_b ? "'" + option_text(*b) + "'" : "(not set)";
    differences += (differences.empty() ? "" : "; ") + ("--" + name + ": the run in this folder has " + was + ", now " + now);
  }
  return differences;
}

void check_run_folder(const std::string& out, RunStart start, const RunOptions& options,
                      const std::vector<std::string>& may_change, const RunRecordUpgrade& upgrade,
                      std::string* warnings) {
  std::error_code ec;
  const auto status = fs::status(out, ec);
  const bool exists = fs::exists(status);
  if (exists && !fs::is_directory(status)) throw std::invalid_argument("--out '" + out + "' exists and is not a folder");
  if (start == RunStart::kFresh && exists) {
    std::vector<std::string> names;
    for (const auto& e : fs::directory_iterator(out, ec)) {
      if (names.size() < 4) names.push_back(e.path().filename().string());
      else break;
    }
    if (ec) throw std::invalid_argument("--out '" + out + "' cannot be listed: " + ec.message());
    if (!names.empty()) {
      std::string listed;
      for (size_t i = 0; i < names.size() && i < 3; ++i) listed += (i ? ", " : "") + names[i];
      if (names.size() > 3) listed += ", ...";
      throw std::invalid_argument("--out '" + out + "' is not empty (" + listed +
                                  "): give --resume to continue the run in it, --overwrite to replace that run, "
                                  "or a new folder");
    }
  }
  if (start != RunStart::kResume) return;
  const std::string last = (fs::path(out) / "last.pt").string();
  if (!fs::exists(last)) throw std::invalid_argument("--resume: " + last + " does not exist");
  const auto record = read_run_record(out);
  if (!record) {
    if (warnings) {
      *warnings += "--resume: " + out + " has no " + kRunConfigFile + " or " + kLegacyRunConfigFile +
                   " (written by an older umvs): the options cannot be compared with the run's; they are recorded now\n";
    }
    return;
  }
  const RunOptions stored = upgrade ? upgrade(*record) : record->options;
  const std::string diff = run_options_difference(stored, options, may_change);
  if (!diff.empty()) {
    throw std::invalid_argument("--resume must continue the same run: " + diff + " (" + record->path +
                                "); start a new run in another folder to change it");
  }
}

std::optional<RunRecord> read_run_record(const std::string& out) {
  RunRecord record;
  record.path = (fs::path(out) / kRunConfigFile).string();
  if (!fs::exists(record.path)) {
    const std::string legacy = (fs::path(out) / kLegacyRunConfigFile).string();
    if (!fs::exists(legacy)) return std::nullopt;
    record.path = legacy;
    record.version = 1;
    record.options = RunOptions::object();
    for (const auto& entry : read_run_config(legacy)) record.options[entry.first] = entry.second;
    return record;
  }
  checked_file_size(record.path, kMaxTextFileBytes, "run configuration");
  std::ifstream in(record.path);
  if (!in) throw std::runtime_error("cannot open run configuration '" + record.path + "'");
  try {
    const nlohmann::json doc = nlohmann::json::parse(in);
    if (doc.value("format", "") != kRunRecordFormat) throw std::runtime_error("not a \"" + std::string(kRunRecordFormat) + "\" record");
    record.version = doc.at("version").get<int>();
    record.options = doc.at("options");
    if (!record.options.is_object()) throw std::runtime_error("\"options\" is not an object");
  } catch (const nlohmann::json::exception& e) {
    throw std::runtime_error("run configuration '" + record.path + "' cannot be read: " + e.what());
  } catch (const std::runtime_error& e) {
    throw std::runtime_error("run configuration '" + record.path + "': " + e.what());
  }
  if (record.version > kRunRecordVersion) {
    throw std::runtime_error("run configuration '" + record.path + "' has version " + std::to_string(record.version) +
                             ", newer than this umvs reads (" + std::to_string(kRunRecordVersion) +
                             "): use the umvs that made the run");
  }
  return record;
}

void write_run_record(const std::string& out, const RunOptions& options) {
  nlohmann::ordered_json doc;  // format and version first, for people reading the file
  doc["format"] = kRunRecordFormat;
  doc["version"] = kRunRecordVersion;
  doc["options"] = options.is_null() ? RunOptions::object() : options;
  write_file_atomically((fs::path(out) / kRunConfigFile).string(), [&](std::ostream& os) { os << doc.dump(2) << "\n"; });
}

RunConfig read_run_config(const std::string& path) {
  checked_file_size(path, kMaxTextFileBytes, "run configuration");
  std::ifstream in(path);
  if (!in) throw std::runtime_error("cannot open run configuration '" + path + "'");
  RunConfig config;
  int number = 0;
  for (std::string line; std::getline(in, line);) {
    ++number;
    if (line.empty() || line[0] == '#') continue;
    const auto eq = line.find('=');
    if (eq == std::string::npos || eq == 0) {
      throw std::runtime_error("run configuration '" + path + "' line " + std::to_string(number) +
                               ": expected name=value");
    }
    config[line.substr(0, eq)] = line.substr(eq + 1);
  }
  return config;
}

void remove_run_files(const std::string& out) {
  for (const auto& name : run_files()) {
    const fs::path p = fs::path(out) / name;
    std::error_code ec;
    fs::remove(p, ec);
    if (ec) throw std::runtime_error("--overwrite: cannot remove " + p.string() + ": " + ec.message());
  }
}

namespace {

template <class Row>
using NumberFields = std::vector<std::pair<std::string, std::optional<double> Row::*>>;

// The numeric columns after the first (step, checkpoint): one list per table, so that the header,
// the writer and the readers cannot disagree.
const NumberFields<TrainLogRow>& train_log_fields() {
  static const NumberFields<TrainLogRow> fields = {
      {"total", &TrainLogRow::total},
      {"photometric", &TrainLogRow::photometric},
      {"ssim", &TrainLogRow::ssim},
      {"smoothness", &TrainLogRow::smoothness},
      {"valid_fraction", &TrainLogRow::valid_fraction},
      {"lr", &TrainLogRow::lr},
      {"seconds", &TrainLogRow::seconds},
      {"val_photometric", &TrainLogRow::val_photometric},
      {"val_total", &TrainLogRow::val_total},
      {"val_abs_err", &TrainLogRow::val_abs_err},
      {"val_within_1pct", &TrainLogRow::val_within_1pct},
      {"supervised", &TrainLogRow::supervised},
      {"entropy", &TrainLogRow::entropy},
      {"plane_loss", &TrainLogRow::plane_loss}};
  return fields;
}

const NumberFields<EvalRow>& eval_fields() {
  static const NumberFields<EvalRow> fields = {
      {"tuples", &EvalRow::tuples},           {"photometric", &EvalRow::photometric},
      {"ssim", &EvalRow::ssim},               {"smoothness", &EvalRow::smoothness},
      {"total", &EvalRow::total},             {"abs_err", &EvalRow::abs_err},
      {"abs_rel", &EvalRow::abs_rel},         {"within_1pct", &EvalRow::within_1pct},
      {"consistent", &EvalRow::consistent}};
  return fields;
}

template <class Row>
std::vector<std::string> columns_of(const std::string& first, const NumberFields<Row>& fields) {
  std::vector<std::string> columns = {first};
  for (const auto& f : fields) columns.push_back(f.first);
  return columns;
}

// ",v1,v2,...": empty cells for values not measured.
template <class Row>
std::string format_fields(const Row& row, const NumberFields<Row>& fields) {
  std::ostringstream s;
  s.precision(7);
  for (const auto& f : fields) {
    s << ",";
    if (const auto& v = row.*(f.second)) s << *v;
  }
  return s.str();
}

template <class Row>
void parse_fields(const CsvRow& csv, const NumberFields<Row>& fields, Row* row) {
  for (const auto& f : fields) row->*(f.second) = csv.number(f.first);
}

std::vector<std::string> split_csv_line(const std::string& line) {
  std::vector<std::string> fields;
  std::stringstream s(line);
  for (std::string f; std::getline(s, f, ',');) fields.push_back(f);
  if (!line.empty() && line.back() == ',') fields.emplace_back();  // a trailing empty cell
  return fields;
}

}  // namespace

const std::vector<std::string>& train_log_columns() {
  static const std::vector<std::string> columns = columns_of("step", train_log_fields());
  return columns;
}

const std::vector<std::string>& eval_columns() {
  static const std::vector<std::string> columns = columns_of("checkpoint", eval_fields());
  return columns;
}

std::string csv_header(const std::vector<std::string>& columns) {
  std::string s;
  for (const auto& c : columns) s += (s.empty() ? "" : ",") + c;
  return s;
}

CsvRow::CsvRow(std::vector<std::string> names, std::vector<std::string> values)
    : names_(std::move(names)), values_(std::move(values)) {}

std::string CsvRow::text(const std::string& name) const {
  for (size_t i = 0; i < names_.size() && i < values_.size(); ++i) {
    if (names_[i] == name) return values_[i];
  }
  return "";
}

std::optional<double> CsvRow::number(const std::string& name) const {
  const std::string cell = text(name);
  if (cell.empty()) return std::nullopt;
  try {
    size_t used = 0;
    const double v = std::stod(cell, &used);
    if (used != cell.size()) return std::nullopt;
    return v;
  } catch (const std::exception&) {
    return std::nullopt;
  }
}

bool read_last_csv_row(const std::string& path, CsvRow* row) {
  std::ifstream in(path);
  std::string header, line, last;
  if (!std::getline(in, header)) return false;
  while (std::getline(in, line)) {
    if (!line.empty()) last = line;
  }
  if (last.empty()) return false;
  *row = CsvRow(split_csv_line(header), split_csv_line(last));
  return true;
}

std::vector<CsvRow> read_csv_rows(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error("cannot read " + path);
  std::string header, line;
  std::getline(in, header);
  const auto names = split_csv_line(header);
  std::vector<CsvRow> rows;
  while (std::getline(in, line)) {
    if (!line.empty()) rows.emplace_back(names, split_csv_line(line));
  }
  if (in.bad()) throw std::runtime_error("cannot read " + path);
  return rows;
}

std::string format_csv_row(const TrainLogRow& row) {
  return std::to_string(row.step) + format_fields(row, train_log_fields());
}

TrainLogRow train_log_row(const CsvRow& csv) {
  TrainLogRow row;
  const auto step = csv.number("step");
  if (!step) throw std::runtime_error("training log row without a step: '" + csv.text("step") + "'");
  row.step = static_cast<int64_t>(*step);
  parse_fields(csv, train_log_fields(), &row);
  return row;
}

std::string format_csv_row(const EvalRow& row) {
  if (row.checkpoint.find_first_of(",\n") != std::string::npos) {
    throw std::invalid_argument("eval.csv: the checkpoint path '" + row.checkpoint + "' has a comma or line break");
  }
  return row.checkpoint + format_fields(row, eval_fields());
}

EvalRow eval_row(const CsvRow& csv) {
  EvalRow row;
  row.checkpoint = csv.text("checkpoint");
  parse_fields(csv, eval_fields(), &row);
  return row;
}

}  // namespace umvs
