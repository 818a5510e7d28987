// Reports of unsup_mvs/jobs/bench.h: one JSON object per run, or the text `umvs bench` prints.
#include <iomanip>
#include <ostream>
#include <sstream>
#include <utility>

#include "unsup_mvs/core/timing_log.h"
#include "unsup_mvs/jobs/bench.h"

namespace umvs {

namespace {

std::pair<double, double> p50_p90(const std::vector<double>& v) { return {percentile(v, 50), percentile(v, 90)}; }

// One estimator's keys of the pipeline's JSON object.
nlohmann::ordered_json pipeline_json(const PipelineTimes& t, const PipelineBenchResult& r) {
  auto pair = [](const std::vector<double>& v) { return nlohmann::ordered_json{{"p50", p50_p90(v).first}, {"p90", p50_p90(v).second}}; };
  return {{"width", r.width}, {"height", r.height}, {"num_depth", t.num_depth}, {"views", r.views},
          {"depth_map_width", t.width}, {"depth_map_height", t.height},
          {"runs", static_cast<int>(t.total.size())}, {"runs_with_per_source_passes", t.extra_passes},
          {"total_s", pair(t.total)}, {"network_all_passes_s", pair(t.network)}, {"first_pass_s", pair(t.first_pass)},
          {"completion_s", pair(t.completion)},
          {"first_pass_stages_p50_s", {{"features", p50_p90(t.features).first}, {"cost_volume", p50_p90(t.volume).first},
                                       {"unet3d", p50_p90(t.unet).first}}}};
}

// One estimator's text block: `header`, then p50/p90 of the estimate and each stage.
void print_pipeline_block(std::ostream& out, const std::string& header, const PipelineTimes& t) {
  auto line = [&out](const std::string& name, const std::vector<double>& v) {
    out << "  " << std::left << std::setw(34) << name << std::right << std::setprecision(3) << "p50 "
        << p50_p90(v).first << " s, p90 " << p50_p90(v).second << " s\n";
  };
  out << header;
  line("image to depth map (estimate)", t.total);
  line("network, every pass", t.network);
  line("  features", t.features);
  line("  cost volume", t.volume);
  line("  " + t.regularizer, t.unet);
  if (t.fine) {
    line("  of the last two, the fine pass", t.fine_pass);
    line("network, first pass", t.first_pass);
  }
  line("completion", t.completion);
}

}  // namespace

nlohmann::ordered_json to_json(const NetworkBenchResult& r, const BenchContext& context) {
  const auto& s = r.stats;
  nlohmann::ordered_json out = {
      {"case", "network"}, {"path", r.path}, {"width", r.width}, {"height", r.height}, {"num_depth", r.num_depth},
      {"views", r.views}, {"threads", context.threads}, {"device", context.device}, {"tuned", context.tuned},
      {"runs", s.runs}, {"median_s", s.median}, {"min_s", s.min}, {"max_s", s.max}, {"gflop", r.gflop},
      {"gflops", r.gflop / s.median}, {"peak_rss_mib", r.peak_rss_mib}, {"minor_faults_per_run", r.minor_faults_per_run}};
  if (r.have_stages) {
    out["stages_median_s"] = {{"features", r.features}, {"cost_volume", r.cost_volume}, {"unet3d", r.regularization},
                              {"regression", r.regression}, {"refinement", r.refinement}};
  }
  if (r.autograd) {
    out["autograd_median_s"] = r.autograd->median;
    out["autograd_over_fast"] = r.autograd->median / s.median;
  }
  return out;
}

void print_text(std::ostream& out, const NetworkBenchResult& r, const BenchContext& context) {
  const auto& s = r.stats;
  out << std::fixed << std::setprecision(3) << r.network << " " << r.width << "x" << r.height << " D=" << r.num_depth
      << " V=" << r.views << " device=" << context.device << " threads=" << context.threads << " path=" << r.path
      << (context.tuned ? "" : " (untuned)") << ": median " << s.median << " s (min " << s.min << ", max " << s.max
      << ", " << s.runs << " runs), " << std::setprecision(1) << r.gflop << " GFLOP -> " << r.gflop / s.median
      << " GFLOP/s, peak RSS " << std::setprecision(0) << r.peak_rss_mib << " MiB, " << r.minor_faults_per_run
      << " minor page faults per run\n";
  if (r.have_stages) {
    out << std::setprecision(4) << "  stages (median s): features " << r.features << ", cost volume " << r.cost_volume
        << ", " << r.regularizer << " " << r.regularization << ", regression " << r.regression;
    if (r.refine) out << ", refinement " << r.refinement;
    out << "\n";
  }
  if (r.autograd) {
    out << std::setprecision(3) << "  autograd path, interleaved: median " << r.autograd->median << " s (min "
        << r.autograd->min << ", max " << r.autograd->max << ") -> autograd / fast = " << r.autograd->median / s.median << "\n";
  }
}

nlohmann::ordered_json to_json(const PipelineBenchResult& r, const BenchContext& context) {
  nlohmann::ordered_json out = {{"case", "pipeline"}};
  out.update(pipeline_json(r.times, r));
  out["threads"] = context.threads;
  out["device"] = context.device;
  out["peak_rss_mib"] = r.peak_rss_mib;
  if (r.against) out["against"] = pipeline_json(*r.against, r);
  return out;
}

void print_text(std::ostream& out, const PipelineBenchResult& r, const BenchContext& context, const std::string& against) {
  const auto& t = r.times;
  std::ostringstream header;
  header << std::fixed << "pipeline (the inference nodelet's defaults) " << r.width << "x" << r.height << " images, D="
         << t.num_depth << ", " << r.views << " views, device=" << context.device << " threads=" << context.threads << ": "
         << t.width << "x" << t.height << " depth maps, " << t.total.size() << " runs (" << t.extra_passes
         << " with the per-source passes of auto), peak RSS " << std::setprecision(0) << r.peak_rss_mib << " MiB\n";
  out << std::fixed;
  print_pipeline_block(out, header.str(), t);
  if (!r.against) return;
  const auto& a = *r.against;
  std::ostringstream against_header;
  against_header << "against (one pass, " << against << "): D=" << a.num_depth << ", " << a.width << "x" << a.height
                 << " depth maps, " << a.total.size() << " runs (" << a.extra_passes << " with the per-source passes of auto)\n";
  print_pipeline_block(out, against_header.str(), a);
  const double c90 = p50_p90(t.total).second, a90 = p50_p90(a.total).second;
  out << std::setprecision(3) << "image to depth map p90: candidate " << c90 << " s, against " << a90
      << " s (against / candidate = " << std::setprecision(2) << a90 / c90 << "x)\n";
}

nlohmann::ordered_json to_json(const FusionBenchResult& r, const BenchContext& context) {
  const auto& s = r.per_view;
  return {{"case", "fusion"}, {"width", r.width}, {"height", r.height}, {"sources", r.sources},
          {"threads", context.threads}, {"device", context.device}, {"runs", s.runs}, {"median_s_per_view", s.median},
          {"min_s", s.min}, {"max_s", s.max}, {"points_per_s", r.points_per_s}, {"points", r.points},
          {"peak_rss_mib", r.peak_rss_mib},
          {"stages_median_s_per_view", {{"ranking", r.ranking_s}, {"consistency", r.consistency_s}, {"points", r.points_s}}}};
}

void print_text(std::ostream& out, const FusionBenchResult& r, const BenchContext& context) {
  const auto& s = r.per_view;
  out << std::fixed << std::setprecision(3) << "fusion " << r.width << "x" << r.height << " reference, " << r.sources
      << " sources, device=" << context.device << " threads=" << context.threads << ": median " << s.median
      << " s per reference view (min " << s.min << ", max " << s.max << ", " << s.runs << " runs of " << r.views
      << " views), " << std::setprecision(0) << r.points_per_s << " points/s (" << r.points << " points per run), peak RSS "
      << r.peak_rss_mib << " MiB\n"
      << std::setprecision(5) << "  stages per view (median s): source ranking " << r.ranking_s << ", consistency "
      << r.consistency_s << ", points " << r.points_s << "\n";
}

}  // namespace umvs
