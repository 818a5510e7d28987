// Reports of unsup_mvs/io/evaluation.h: JSON and the tables `umvs eval depth|cloud` print.
#include <algorithm>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <ostream>
#include <sstream>

#include "unsup_mvs/io/evaluation.h"

namespace umvs {

namespace {

std::string format(const char* fmt, ...) __attribute__((format(printf, 1, 2)));
std::string format(const char* fmt, ...) {
  char buf[256];
  va_list args;
  va_start(args, fmt);
  std::vsnprintf(buf, sizeof(buf), fmt, args);
  va_end(args);
  return buf;
}

std::string pct(double share) { return format("%6.2f", 100.0 * share); }
std::string num(double v, const char* fmt = "%10.5g") {
  if (!std::isfinite(v)) return std::string(10 - 3, ' ') + "nan";
  return format(fmt, v);
}
std::string threshold_label(double t) {
  std::ostringstream os;
  os << t;
  return os.str();
}

nlohmann::ordered_json depth_json(const DepthMetrics& m) {
  return {{"gt_pixels", m.gt_pixels}, {"evaluated_pixels", m.evaluated_pixels}, {"completeness", m.completeness()},
          {"mae", m.mae}, {"abs_rel", m.abs_rel}, {"rmse", m.rmse},
          {"within_rel", m.within_rel}, {"within_abs", m.within_abs}};
}

}  // namespace

nlohmann::ordered_json to_json(const DepthFolderEvaluation& eval, const DepthFolderEvalOptions& options) {
  nlohmann::ordered_json out = {{"rel_thresholds", options.metrics.rel_thresholds},
                                {"abs_thresholds", options.metrics.abs_thresholds}};
  if (options.sparsification) {
    const auto& curve = eval.curve;
    out["sparsification"] = {{"kept", curve.kept}, {"abs_rel", curve.abs_rel}, {"oracle", curve.oracle}, {"ause", curve.ause}};
    out["confident"] = nlohmann::ordered_json::array();
    for (const auto& c : eval.confident) {
      out["confident"].push_back({{"level", c.level}, {"image_share", c.image_share()}, {"scored_pixels", c.scored},
                                  {"abs_rel", c.abs_rel}, {"within", c.within}, {"within_rel", options.confident_within}});
    }
  }
  out["views"] = nlohmann::ordered_json::array();
  for (size_t i = 0; i < eval.views.size(); ++i) {
    nlohmann::ordered_json view = {{"view", eval.views[i]}};
    view.update(depth_json(eval.per_view[i]));
    if (eval.split()) {
      view["seen_share"] = seen_share(eval.per_view_seen[i], eval.per_view_unseen[i]);
      view["seen"] = depth_json(eval.per_view_seen[i]);
      view["unseen"] = depth_json(eval.per_view_unseen[i]);
    }
    out["views"].push_back(view);
  }
  out["overall"] = depth_json(eval.overall);
  if (eval.split()) {
    out["covisibility_sources"] = options.covisibility_sources;
    out["overall"]["seen_share"] = seen_share(eval.seen, eval.unseen);
    out["seen"] = depth_json(eval.seen);
    out["unseen"] = depth_json(eval.unseen);
  }
  return out;
}

void print_table(std::ostream& out, const DepthFolderEvaluation& eval, const DepthFolderEvalOptions& options,
                 const std::string& gt_root) {
  const auto& rel = options.metrics.rel_thresholds;
  const auto& abs = options.metrics.abs_thresholds;
  out << "depth: " << eval.est_dir << " vs " << gt_root << "/depth_gt (shares in % of evaluated pixels)\n";
  out << "    view        MAE    abs rel";
  for (double t : rel) out << std::string(std::max<int>(1, 8 - 2 - static_cast<int>(threshold_label(100 * t).size())), ' ') << "<" << threshold_label(100 * t) << "%";
  for (double t : abs) out << "  <" << threshold_label(t);
  out << "  complete%\n";
  const auto row = [&](const std::string& name, const DepthMetrics& m) {
    out << format("%8s %10s %10s", name.c_str(), num(m.mae).c_str(), num(m.abs_rel).c_str());
    for (size_t i = 0; i < m.within_rel.size(); ++i) {
      const int w = static_cast<int>(threshold_label(100 * rel[i]).size()) + 4;
      out << format("%*s", std::max(w, 8), pct(m.within_rel[i]).c_str());
    }
    for (size_t i = 0; i < m.within_abs.size(); ++i) {
      const int w = static_cast<int>(threshold_label(abs[i]).size()) + 3;
      out << format("%*s", std::max(w, 7), pct(m.within_abs[i]).c_str());
    }
    out << format("  %9s\n", pct(m.completeness()).c_str());
  };
  for (size_t i = 0; i < eval.views.size(); ++i) row(std::to_string(eval.views[i]), eval.per_view[i]);
  row("overall", eval.overall);
  if (eval.split()) {
    row("seen", eval.seen);
    row("unseen", eval.unseen);
    out << format("seen: %s %% of the ground-truth pixels lie in one of the first %d neighbours' views, unhidden\n",
                  pct(seen_share(eval.seen, eval.unseen)).c_str(), options.covisibility_sources);
  }
  if (!options.sparsification) return;
  out << "\nsparsification (abs rel of the most confident share of the evaluated pixels; oracle: of least error)\n";
  out << "    kept%  abs rel   oracle\n";
  for (size_t i = 0; i < eval.curve.kept.size(); ++i) {
    out << format("  %6.0f  %7.4f  %7.4f\n", 100 * eval.curve.kept[i], eval.curve.abs_rel[i], eval.curve.oracle[i]);
  }
  out << format("AUSE %.4f\n\n", eval.curve.ause);
  out << format("confidence >=   image%%   abs rel   within %g%%\n", 100 * options.confident_within);
  for (const auto& c : eval.confident) {
    out << format("%13g  %7s  %8s  %10s\n", c.level, pct(c.image_share()).c_str(), num(c.abs_rel, "%8.4f").c_str(),
                  pct(c.within).c_str());
  }
}

nlohmann::ordered_json to_json(const CloudMetrics& m) {
  return {{"est_points", m.est_points}, {"gt_points", m.gt_points}, {"accuracy_mean", m.accuracy_mean},
          {"accuracy_median", m.accuracy_median}, {"completeness_mean", m.completeness_mean},
          {"completeness_median", m.completeness_median}, {"overall", m.overall},
          {"accuracy_outliers", m.accuracy_outliers}, {"completeness_outliers", m.completeness_outliers},
          {"thresholds", m.thresholds}, {"precision", m.precision}, {"recall", m.recall},
          {"fscore", m.fscore}};
}

void print_table(std::ostream& out, const CloudMetrics& m, const std::string& est_name, const std::string& gt_name,
                 bool downsampled) {
  out << "cloud: " << est_name << " (" << m.est_points << " points) vs " << gt_name << " (" << m.gt_points << " points)"
      << (downsampled ? ", after downsampling" : "") << "\n";
  out << "              mean      median   outliers%\n";
  out << format("accuracy  %10s  %10s   %7s\n", num(m.accuracy_mean).c_str(), num(m.accuracy_median).c_str(), pct(m.accuracy_outliers).c_str());
  out << format("complete  %10s  %10s   %7s\n", num(m.completeness_mean).c_str(), num(m.completeness_median).c_str(),
                pct(m.completeness_outliers).c_str());
  out << format("overall   %10s\n", num(m.overall).c_str());
  out << "\n threshold  precision%  recall%  F-score%\n";
  for (size_t i = 0; i < m.thresholds.size(); ++i) {
    out << format("%10s  %10s  %7s  %8s\n", num(m.thresholds[i], "%.4g").c_str(), pct(m.precision[i]).c_str(),
                  pct(m.recall[i]).c_str(), pct(m.fscore[i]).c_str());
  }
}

}  // namespace umvs
