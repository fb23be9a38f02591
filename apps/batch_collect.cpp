#include "batch_collect.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>

#include "batch_dispatch.hpp"
#include "batch_job.hpp"
#include "planeslam/datasets/atomic_file.hpp"
#include "planeslam/datasets/errors.hpp"
#include "svg_plot.hpp"

namespace planeslam::app {
namespace {

namespace fs = std::filesystem;
namespace ds = planeslam::datasets;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

/// The figures of one job's row (NaN where the job has none).
struct JobRow {
  std::string sequence, variant, status, error;
  int exit_code = -1;
  double ate_rmse = kNaN, ate_mean = kNaN, ate_max = kNaN;
  double rpe_t_rmse = kNaN, rpe_r_rmse = kNaN;
  double frames = kNaN, fps = kNaN, keyframes = kNaN, loop_closures = kNaN;
  bool HasFigures() const { return status == "ok" || status == "skipped_frames"; }
};

/// The columns of the table: name, unit of the CSV/JSON value, Markdown scale and unit, and
/// whether lower is better (for "worst").
struct Column {
  const char* key;
  double JobRow::*field;
  double md_scale;
  const char* md_header;
  bool lower_is_better;
  bool integer;  ///< a count (written without a fraction)
};

const std::vector<Column>& Columns() {
  static const std::vector<Column> columns = {
      {"ate_rmse_m", &JobRow::ate_rmse, 100.0, "ATE rmse [cm]", true, false},
      {"ate_mean_m", &JobRow::ate_mean, 100.0, "ATE mean [cm]", true, false},
      {"ate_max_m", &JobRow::ate_max, 100.0, "ATE max [cm]", true, false},
      {"rpe_translation_rmse_m_per_frame", &JobRow::rpe_t_rmse, 100.0, "RPE t rmse [cm/frame]", true, false},
      {"rpe_rotation_rmse_deg_per_frame", &JobRow::rpe_r_rmse, 1.0, "RPE r rmse [deg/frame]", true, false},
      {"frames", &JobRow::frames, 1.0, "frames", false, true},
      {"frames_per_second", &JobRow::fps, 1.0, "frames/s", false, false},
      {"keyframes", &JobRow::keyframes, 1.0, "keyframes", false, true},
      {"loop_closures", &JobRow::loop_closures, 1.0, "loop closures", false, true},
  };
  return columns;
}

nlohmann::json ReadJsonFile(const fs::path& path) {
  std::ifstream in(path);
  if (!in) return nullptr;
  try {
    return nlohmann::json::parse(in);
  } catch (const nlohmann::json::exception&) {
    return nullptr;
  }
}

double Number(const nlohmann::json& j, std::initializer_list<const char*> keys) {
  const nlohmann::json* node = &j;
  for (const char* k : keys) {
    if (!node->is_object() || !node->contains(k)) return kNaN;
    node = &(*node)[k];
  }
  return node->is_number() ? node->get<double>() : kNaN;
}

JobRow ReadRow(const std::string& batch_dir, const BatchJob& job) {
  JobRow row;
  row.sequence = job.sequence;
  row.variant = job.variant;
  const JobStatus s = ReadJobStatus(batch_dir, job);
  if (s.record.is_object()) row.exit_code = s.record.value("exit_code", -1);
  switch (s.state) {
    case JobState::kMissing: row.status = "not run"; break;
    case JobState::kFailed: row.status = s.record.value("status", std::string("failed")); break;
    case JobState::kOutdated: row.status = "outdated"; break;
    case JobState::kComplete: row.status = s.record.value("status", std::string("ok")); break;
  }
  if (s.state != JobState::kComplete) {
    row.error = s.state == JobState::kOutdated ? "made with other settings; rerun the batch"
                                               : s.Error();
    return row;
  }
  const fs::path dir = fs::path(batch_dir) / job.sequence / job.variant;
  const nlohmann::json metrics = ReadJsonFile(dir / "metrics.json");
  const nlohmann::json summary = ReadJsonFile(dir / "summary.json");
  row.ate_rmse = Number(metrics, {"ate", "rmse"});
  row.ate_mean = Number(metrics, {"ate", "mean"});
  row.ate_max = Number(metrics, {"ate", "max"});
  row.rpe_t_rmse = Number(metrics, {"rpe_translation_m_per_frame", "rmse"});
  row.rpe_r_rmse = Number(metrics, {"rpe_rotation_deg_per_frame", "rmse"});
  row.frames = Number(summary, {"frames"});
  row.fps = Number(summary, {"frames_per_second"});
  row.keyframes = Number(summary, {"keyframes"});
  row.loop_closures = Number(summary, {"loop_closures"});
  if (metrics.is_null()) row.error = "no metrics.json (no ground truth)";
  if (row.status == "skipped_frames") {
    row.error = std::to_string(summary.value("skipped_frames", 0)) + " unreadable frame(s) skipped";
  }
  return row;
}

/// Mean and worst of one column over a variant's sequences with figures.
struct Aggregate {
  std::string variant;
  int with_figures = 0, jobs = 0;
  std::vector<double> mean, worst;  ///< per column
};

std::vector<Aggregate> Aggregates(const std::vector<JobRow>& rows,
                                  const std::vector<std::string>& variants) {
  std::vector<Aggregate> out;
  for (const std::string& v : variants) {
    Aggregate a;
    a.variant = v;
    for (const Column& c : Columns()) {
      double sum = 0.0, worst = kNaN;
      int n = 0;
      for (const JobRow& r : rows) {
        if (r.variant != v || !r.HasFigures() || !std::isfinite(r.*c.field)) continue;
        sum += r.*c.field;
        ++n;
        const double x = r.*c.field;
        if (std::isnan(worst) || (c.lower_is_better ? x > worst : x < worst)) worst = x;
      }
      a.mean.push_back(n > 0 ? sum / n : kNaN);
      a.worst.push_back(worst);
    }
    for (const JobRow& r : rows) {
      if (r.variant != v) continue;
      ++a.jobs;
      a.with_figures += r.HasFigures() ? 1 : 0;
    }
    out.push_back(std::move(a));
  }
  return out;
}

std::string Md(double value, double scale) {
  if (!std::isfinite(value)) return "–";
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%.4g", value * scale);
  return buffer;
}

std::string Csv(double value) {
  if (!std::isfinite(value)) return "";
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%.17g", value);
  return buffer;
}

std::string CsvText(const std::string& text) {
  if (text.find_first_of(",\"\n") == std::string::npos) return text;
  std::string q = "\"";
  for (char c : text) q += c == '"' ? std::string("\"\"") : std::string(1, c);
  return q + "\"";
}

nlohmann::json JsonNumber(double value) {
  return std::isfinite(value) ? nlohmann::json(value) : nlohmann::json(nullptr);
}

std::string MarkdownTables(const std::vector<JobRow>& rows, const std::vector<Aggregate>& aggs) {
  std::ostringstream md;
  md << "| sequence | variant | status |";
  for (const Column& c : Columns()) md << " " << c.md_header << " |";
  md << "\n|---|---|---|";
  for (std::size_t i = 0; i < Columns().size(); ++i) md << "---:|";
  md << "\n";
  for (const JobRow& r : rows) {
    md << "| " << r.sequence << " | " << r.variant << " | "
       << (r.HasFigures() ? r.status : "**" + r.status + "**") << " |";
    for (const Column& c : Columns()) md << " " << Md(r.*c.field, c.md_scale) << " |";
    md << "\n";
  }
  md << "\nPer variant over its sequences: mean / worst (highest error, lowest frames/s)\n\n"
     << "| variant | jobs with figures |";
  for (const Column& c : Columns()) md << " " << c.md_header << " |";
  md << "\n|---|---:|";
  for (std::size_t i = 0; i < Columns().size(); ++i) md << "---:|";
  md << "\n";
  for (const Aggregate& a : aggs) {
    md << "| " << a.variant << " | " << a.with_figures << "/" << a.jobs
       << (a.with_figures < a.jobs ? " **incomplete**" : "") << " |";
    for (std::size_t i = 0; i < Columns().size(); ++i) {
      const Column& c = Columns()[i];
      md << " " << Md(a.mean[i], c.md_scale);
      if (!c.integer) md << " / " << Md(a.worst[i], c.md_scale);
      md << " |";
    }
    md << "\n";
  }
  bool any = false;
  for (const JobRow& r : rows) {
    if (r.error.empty()) continue;
    if (!any) md << "\nJobs without full figures:\n\n";
    any = true;
    md << "- " << r.sequence << "/" << r.variant << ": " << r.error << "\n";
  }
  return md.str();
}

std::string JobsCsv(const std::vector<JobRow>& rows) {
  std::ostringstream csv;
  csv << "sequence,variant,status,exit_code";
  for (const Column& c : Columns()) csv << "," << c.key;
  csv << ",error\n";
  for (const JobRow& r : rows) {
    csv << CsvText(r.sequence) << "," << CsvText(r.variant) << "," << r.status << ","
        << (r.exit_code >= 0 ? std::to_string(r.exit_code) : "");
    for (const Column& c : Columns()) csv << "," << Csv(r.*c.field);
    csv << "," << CsvText(r.error) << "\n";
  }
  return csv.str();
}

std::string VariantsCsv(const std::vector<Aggregate>& aggs) {
  std::ostringstream csv;
  csv << "variant,jobs,jobs_with_figures";
  for (const Column& c : Columns()) csv << ",mean_" << c.key << ",worst_" << c.key;
  csv << "\n";
  for (const Aggregate& a : aggs) {
    csv << CsvText(a.variant) << "," << a.jobs << "," << a.with_figures;
    for (std::size_t i = 0; i < Columns().size(); ++i) {
      csv << "," << Csv(a.mean[i]) << "," << Csv(a.worst[i]);
    }
    csv << "\n";
  }
  return csv.str();
}

nlohmann::json ResultsJson(const std::vector<JobRow>& rows, const std::vector<Aggregate>& aggs) {
  nlohmann::json j;
  j["jobs"] = nlohmann::json::array();
  for (const JobRow& r : rows) {
    nlohmann::json row = {{"sequence", r.sequence}, {"variant", r.variant}, {"status", r.status}};
    row["exit_code"] = r.exit_code >= 0 ? nlohmann::json(r.exit_code) : nlohmann::json(nullptr);
    for (const Column& c : Columns()) {
      const double x = r.*c.field;
      row[c.key] = c.integer && std::isfinite(x) ? nlohmann::json(static_cast<std::int64_t>(x))
                                                 : JsonNumber(x);
    }
    row["error"] = r.error;
    j["jobs"].push_back(row);
  }
  j["variants"] = nlohmann::json::array();
  for (const Aggregate& a : aggs) {
    nlohmann::json v = {{"variant", a.variant}, {"jobs", a.jobs}, {"jobs_with_figures", a.with_figures}};
    for (std::size_t i = 0; i < Columns().size(); ++i) {
      v["mean"][Columns()[i].key] = JsonNumber(a.mean[i]);
      v["worst"][Columns()[i].key] = JsonNumber(a.worst[i]);
    }
    j["variants"].push_back(v);
  }
  return j;
}

/// One plot per figure like evo_res: a group of bars per sequence, one bar per variant (drawn as
/// thick vertical lines); a job without the figure leaves its bar out.
void ComparePlot(const std::string& path, const std::string& title, const std::string& y_label,
                 double JobRow::*field, double scale, const std::vector<JobRow>& rows,
                 const BatchPlan& plan) {
  SvgPlot plot(title, "sequence", y_label);
  const int sequences = static_cast<int>(plan.sequences.size());
  const int variants = static_cast<int>(plan.variants.size());
  const int width = std::max(560, 45 * sequences * variants + 240);
  plot.SetSize(width, 400);
  std::vector<std::string> names;
  for (const auto& s : plan.sequences) names.push_back(s.name);
  plot.SetXCategories(names);
  // Each group takes 80 % of its category's width; the plot area is the width less ~105 px.
  const double group = 0.8, slot = group / variants;
  const double bar_px = 0.85 * slot * (width - 105.0) / sequences;
  double highest = 0.0;
  for (int v = 0; v < variants; ++v) {
    std::vector<double> x, y;
    for (int s = 0; s < sequences; ++s) {
      for (const JobRow& r : rows) {
        if (r.sequence != names[s] || r.variant != plan.variants[v].name || !r.HasFigures() ||
            !std::isfinite(r.*field)) {
          continue;
        }
        const double cx = s + 1.0 - 0.5 * group + (v + 0.5) * slot;
        x.insert(x.end(), {cx, cx, kNaN});
        y.insert(y.end(), {0.0, r.*field * scale, kNaN});
        highest = std::max(highest, r.*field * scale);
      }
    }
    plot.AddLine(x, y, LineStyle{CycleColor(v), bar_px, false});
    plot.AddScatter({}, {}, CycleColor(v), plan.variants[v].name);  // the legend entry
  }
  // Headroom above the highest bar for the legend box (18 px a line in a 300 px high plot area),
  // held by an invisible point.
  const double legend_fraction = std::min(0.6, (24.0 + 18.0 * variants) / 300.0);
  plot.AddScatter({1.0}, {highest / (1.0 - legend_fraction)}, SvgColor{255, 255, 255}, "", 0.0);
  plot.Write(path);
}

}  // namespace

nlohmann::json PlanJson(const BatchPlan& plan, const std::string& binary,
                        const std::string& batch_dir) {
  nlohmann::json j;
  j["manifest"] = plan.manifest;
  for (const auto& s : plan.sequences) j["sequences"].push_back(s.name);
  for (const auto& v : plan.variants) j["variants"].push_back(v.name);
  j["jobs"] = nlohmann::json::array();
  for (const BatchJob& job : plan.jobs) {
    j["jobs"].push_back({{"name", job.name},
                         {"sequence", job.sequence},
                         {"variant", job.variant},
                         {"args", job.run_args},
                         {"command", RunCommandLine(binary, batch_dir, job)}});
  }
  return j;
}

BatchPlan ReadPlanJson(const std::string& batch_dir) {
  const std::string path = BatchMetaDir(batch_dir) + "/jobs.json";
  const nlohmann::json j = ReadJsonFile(path);
  if (j.is_null()) {
    throw IoError(path, fs::exists(path) ? "not valid JSON"
                                         : "missing: not the output folder of a planeslam batch");
  }
  BatchPlan plan;
  try {
    plan.manifest = j.at("manifest").get<std::string>();
    for (const auto& s : j.at("sequences")) plan.sequences.push_back({s.get<std::string>(), "", "", "", {}, {}, {}});
    for (const auto& v : j.at("variants")) plan.variants.push_back({v.get<std::string>(), {}, {}, ""});
    for (const auto& job : j.at("jobs")) {
      plan.jobs.push_back({job.at("name").get<std::string>(), job.at("sequence").get<std::string>(),
                           job.at("variant").get<std::string>(),
                           job.at("args").get<std::vector<std::string>>()});
    }
  } catch (const nlohmann::json::exception& e) {
    throw IoError(path, std::string("malformed: ") + e.what());
  }
  return plan;
}

CollectOutput CollectBatch(const std::string& batch_dir) {
  const BatchPlan plan = ReadPlanJson(batch_dir);
  std::vector<JobRow> rows;
  CollectOutput out;
  for (const BatchJob& job : plan.jobs) {
    rows.push_back(ReadRow(batch_dir, job));
    const JobRow& r = rows.back();
    if (r.HasFigures()) ++out.complete;
    else if (r.status == "not run" || r.status == "outdated") ++out.missing;
    else ++out.failed;
  }
  std::vector<std::string> variants;
  for (const auto& v : plan.variants) variants.push_back(v.name);
  const std::vector<Aggregate> aggs = Aggregates(rows, variants);
  out.markdown = MarkdownTables(rows, aggs);
  const fs::path dir(batch_dir);
  const auto write = [&](const std::string& name, const std::string& text) {
    ds::WriteFileAtomic((dir / name).string(), text);
    out.files.push_back((dir / name).string());
  };
  write("results.md", out.markdown);
  write("results.csv", JobsCsv(rows));
  write("results_variants.csv", VariantsCsv(aggs));
  write("results.json", ResultsJson(rows, aggs).dump(2) + "\n");
  ComparePlot((dir / "compare_ate.svg").string(), "ATE per sequence and variant (SE(3) aligned)",
              "ATE rmse [cm]", &JobRow::ate_rmse, 100.0, rows, plan);
  ComparePlot((dir / "compare_rpe.svg").string(), "RPE per sequence and variant (1 frame)",
              "RPE translation rmse [cm/frame]", &JobRow::rpe_t_rmse, 100.0, rows, plan);
  ComparePlot((dir / "compare_fps.svg").string(), "Speed per sequence and variant", "frames/s",
              &JobRow::fps, 1.0, rows, plan);
  for (const char* svg : {"compare_ate.svg", "compare_rpe.svg", "compare_fps.svg"}) {
    out.files.push_back((dir / svg).string());
  }
  return out;
}

}  // namespace planeslam::app
