// The output folder of one `umvs train` run and the run's configuration, so that nothing a user
// had is replaced by accident: a new run starts only in an empty (or new) folder unless the
// user asks to overwrite, and a resumed run must be the same run (same data, sizes, loss,
// optimiser, seed, ...) as the one that wrote the folder.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace umvs {

// The options of a run: option name (without --) -> typed value (number, text, 0/1 option as a
// bool, list as an array of text), as given or defaulted. Stored in OUT/run_config.json.
using RunOptions = nlohmann::json;

enum class RunStart {
  kFresh,      // OUT must be missing or empty
  kResume,     // OUT/last.pt must exist; the options must equal the recorded ones
  kOverwrite,  // OUT may hold an earlier run; its files (run_files()) are replaced
};

// The files `umvs train` writes into its run folder.
const std::vector<std::string>& run_files();

// The record of a run's options: OUT/run_config.json,
//   {"format": "umvs train run", "version": 2, "options": {"batch": 1, "data": ["/abs/path"], ...}}.
// Folders of older versions hold OUT/run_config.txt instead ("name=value" lines): version 1,
// every value text. The version changes when an option is added that changes what a run
// computes; upgrade_train_record (jobs/train_options.h) brings older records to this one.
constexpr const char* kRunConfigFile = "run_config.json";
constexpr const char* kLegacyRunConfigFile = "run_config.txt";
constexpr const char* kRunRecordFormat = "umvs train run";
constexpr int kRunRecordVersion = 2;

struct RunRecord {
  std::string path;     // the file it was read from
  int version = kRunRecordVersion;
  RunOptions options;   // an object; version 1: every value a string
};
// The record in `out`: run_config.json, else run_config.txt; nullopt when it has neither. Throws
// std::runtime_error naming the file when it is malformed, of another format or of a newer version.
std::optional<RunRecord> read_run_record(const std::string& out);
// Writes OUT/run_config.json atomically (version kRunRecordVersion).
void write_run_record(const std::string& out, const RunOptions& options);
// The "name=value" lines of a run_config.txt. Throws std::runtime_error naming the file when
// malformed.
using RunConfig = std::map<std::string, std::string>;
RunConfig read_run_config(const std::string& path);

// Brings a record of an older version to the current one (the options it ran with, in today's
// terms).
using RunRecordUpgrade = std::function<RunOptions(const RunRecord&)>;

// Checks, without changing anything, that a run may start in `out`. Throws std::invalid_argument
// naming the problem: OUT is not a folder; kFresh and OUT is not empty (says to give --resume or
// --overwrite); kResume and OUT/last.pt is missing, or an option differs from the recorded ones
// (read_run_record, then `upgrade` when given; names every such option and both values). Options
// in `may_change` (e.g. the step count) are not compared. A run folder without a record (written
// before there was one) is accepted for kResume with a warning on `warnings`.
void check_run_folder(const std::string& out, RunStart start, const RunOptions& options,
                      const std::vector<std::string>& may_change, const RunRecordUpgrade& upgrade,
                      std::string* warnings);

// Every option whose value differs, in name order, as "--NAME: the run in OUT has A, now B" joined
// by "; "; "" when none. Values are shown as on the command line ('0.5', '1' for true, 'a,b' for a
// list); options missing on one side count as differing ("(not set)").
std::string run_options_difference(const RunOptions& stored, const RunOptions& current,
                                   const std::vector<std::string>& may_change);
// A value as on the command line: "0.5", "1"/"0" for a bool, "a,b" for a list.
std::string option_text(const nlohmann::json& value);

// kOverwrite: removes the files of run_files() from `out` (nothing else); throws
// std::runtime_error naming a file that cannot be removed.
void remove_run_files(const std::string& out);

// The tables of a run, defined once for `umvs train` (the writer) and their readers (the trainer
// node, resume, scripts): OUT/train_log.csv, one row per step, and OUT/eval.csv, the one row of
// --eval-only. An empty cell is a value not measured (no validation at that step, no ground truth):
// std::nullopt in the row structs.
const std::vector<std::string>& train_log_columns();
const std::vector<std::string>& eval_columns();
std::string csv_header(const std::vector<std::string>& columns);  // "a,b,c"

// A row of a CSV table, read by column name.
class CsvRow {
 public:
  CsvRow() = default;
  CsvRow(std::vector<std::string> names, std::vector<std::string> values);
  // The number in column `name`; nullopt when the column is missing, empty or not a number.
  std::optional<double> number(const std::string& name) const;
  // The text in column `name`; "" when missing.
  std::string text(const std::string& name) const;

 private:
  std::vector<std::string> names_, values_;
};
// The last non-empty row of a CSV file with a header line; false when the file is missing or has
// no row.
bool read_last_csv_row(const std::string& path, CsvRow* row);
// Every non-empty row; throws std::runtime_error naming the file when it cannot be read.
std::vector<CsvRow> read_csv_rows(const std::string& path);

// One row of OUT/train_log.csv (columns train_log_columns(), in this order).
struct TrainLogRow {
  int64_t step = 0;
  std::optional<double> total, photometric, ssim, smoothness, valid_fraction, lr, seconds;
  std::optional<double> val_photometric, val_total, val_abs_err, val_within_1pct;  // at validation steps
  std::optional<double> supervised;
  std::optional<double> entropy;  // of the photometric tuples' volumes, when train's --entropy-weight > 0
  std::optional<double> plane_loss;  // their expected plane loss, when train's --plane-loss-weight > 0
};
std::string format_csv_row(const TrainLogRow& row);
// Throws std::runtime_error when the row has no step.
TrainLogRow train_log_row(const CsvRow& row);

// The one row of OUT/eval.csv (columns eval_columns(), in this order).
struct EvalRow {
  std::string checkpoint;
  std::optional<double> tuples, photometric, ssim, smoothness, total;
  std::optional<double> abs_err, abs_rel, within_1pct;  // with ground truth only
  std::optional<double> consistent;                     // share of depth that other views confirm
};
std::string format_csv_row(const EvalRow& row);
EvalRow eval_row(const CsvRow& row);

}  // namespace umvs
