// `planeslam eval ape|rpe|kitti REF EST`: trajectory metrics with evo's semantics (default) or the
// TUM RGB-D benchmark tools' (--tum), and the KITTI odometry benchmark's segment errors (kitti),
// printed as `name value` lines, optionally as JSON and SVG plots.
#include <cmath>
#include <cstdio>
#include <iostream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "cli_common.hpp"
#include "command_registry.hpp"
#include "kitti_report.hpp"
#include "planeslam/datasets/atomic_file.hpp"
#include "exit_codes.hpp"
#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/kitti_odometry_eval.hpp"
#include "planeslam/datasets/trajectory_eval.hpp"
#include "planeslam/datasets/trajectory_io.hpp"
#include "svg_plot.hpp"
#include "trajectory_plots.hpp"

namespace planeslam::app {
namespace {

namespace ds = planeslam::datasets;
constexpr double kPi = 3.14159265358979323846;

/// Python's repr of a float (evo prints its delta that way): shortest digits, ".0" if integral.
std::string PyFloat(double v) {
  std::string s = ds::FormatRoundTrip(v);
  if (s.find_first_of(".eEn") == std::string::npos) s += ".0";
  return s;
}

/// evo's Result.pretty_str: sorted statistic names right-aligned to 10, a tab, six decimals.
std::string EvoStatsBlock(const ds::ErrorStatistics& s) {
  std::ostringstream os;
  char line[96];
  const std::pair<const char*, double> rows[] = {
      {"max", s.max},   {"mean", s.mean}, {"median", s.median}, {"min", s.min},
      {"rmse", s.rmse}, {"sse", s.sse},   {"std", s.std}};
  for (const auto& [name, value] : rows) {
    std::snprintf(line, sizeof(line), "%10s\t%.6f\n", name, value);
    os << line;
  }
  std::snprintf(line, sizeof(line), "%10s\t%zu\n", "pairs", s.count);
  os << line;
  return os.str();
}

/// evaluate_ate.py / evaluate_rpe.py verbose lines: `prefix.stat value unit`.
std::string TumStatsBlock(const std::string& prefix, const ds::ErrorStatistics& s,
                          const std::string& unit) {
  std::ostringstream os;
  const std::pair<const char*, double> rows[] = {{"rmse", s.rmse},     {"mean", s.mean},
                                                 {"median", s.median}, {"std", s.std},
                                                 {"min", s.min},       {"max", s.max}};
  for (const auto& [name, value] : rows) {
    os << prefix << "." << name << " " << Fixed6(value) << " " << unit << "\n";
  }
  return os.str();
}

nlohmann::json StatsJson(const ds::ErrorStatistics& s) {
  return {{"rmse", s.rmse}, {"mean", s.mean}, {"median", s.median}, {"std", s.std},
          {"min", s.min},   {"max", s.max},   {"sse", s.sse},       {"pairs", s.count}};
}

class EvalCommand : public Command {
 public:
  std::string Name() const override { return "eval"; }
  std::string Summary() const override {
    return "Trajectory error (APE/RPE) like evo or the TUM RGB-D tools, KITTI segment errors";
  }
  int Order() const override { return 30; }

  void Setup(CLI::App& sub) override {
    sub.add_option("metric", metric_,
                   "ape (absolute pose error), rpe (relative pose error) or kitti (the KITTI "
                   "odometry benchmark's segment errors)")
        ->required()
        ->check(CLI::IsMember({"ape", "rpe", "kitti"}));
    sub.add_option("ref", ref_path_, "reference (ground-truth) trajectory file")->required();
    sub.add_option("est", est_path_, "estimated trajectory file")->required();
    sub.add_option("--format", format_,
                   "file format of both files: tum, kitti or euroc (default: detected per file)")
        ->check(CLI::IsMember({"tum", "kitti", "euroc"}));
    sub.add_option("--ref-times", ref_times_, "KITTI times file of the reference");
    sub.add_option("--est-times", est_times_, "KITTI times file of the estimate");
    sub.add_flag("--tum", tum_,
                 "TUM RGB-D tools' semantics: associate.py pairs (0.02 s, one to one) and Horn "
                 "alignment for ape (evaluate_ate.py); evaluate_rpe.py pairing and error for rpe");
    t_max_diff_opt_ = sub.add_option("--t-max-diff", t_max_diff_,
                                     "max. time difference to associate stamps [s] (evo 0.01, "
                                     "--tum 0.02)");
    sub.add_option("--t-offset", t_offset_, "time offset added to the estimate's stamps [s]");
    sub.add_flag("-a,--align", align_, "SE(3) Umeyama alignment of the estimate (evo -a)");
    sub.add_flag("-s,--correct-scale", correct_scale_,
                 "with --align: Sim(3) alignment; alone: scale correction only (as evo)");
    sub.add_flag("--align-origin", align_origin_,
                 "move the estimate's first pose onto the reference's");
    sub.add_option("--n-to-align", n_to_align_, "align with the first N pairs only (-1 = all)");
    sub.add_option("-r,--pose-relation", relation_,
                   "error measure: trans_part [m], angle_deg, angle_rad, rot_part, full")
        ->check(CLI::IsMember({"trans_part", "angle_deg", "angle_rad", "rot_part", "full"}));
    sub.add_option("-d,--delta", delta_, "rpe: distance between the poses of a pair (default 1)");
    delta_unit_opt_ = sub.add_option("-u,--delta-unit", delta_unit_,
                                     "rpe: unit of delta: f (frames), m, deg, rad (evo; default f) "
                                     "or s (--tum only; its default)")
                          ->check(CLI::IsMember({"f", "m", "deg", "rad", "s"}));
    sub.add_flag("--all-pairs", all_pairs_, "rpe (evo): every pair at delta, not consecutive ones");
    sub.add_option("--rel-delta-tol", rel_delta_tol_,
                   "rpe (evo) --all-pairs: tolerance relative to delta for m/deg/rad");
    sub.add_flag("--fixed-delta", fixed_delta_,
                 "rpe --tum: pairs (i, frame nearest t_i + delta) instead of all/random pairs");
    sub.add_option("--max-pairs", max_pairs_, "rpe --tum: at most this many pairs (0 = all)");
    sub.add_option("--scale", scale_,
                   "scale applied to the estimate's positions (ape) or motions (rpe --tum), as the "
                   "TUM tools' --scale");
    sub.add_option("--seed", seed_, "rpe --tum: seed of the random pair sampling");
    sub.add_option("--lengths", kitti_.lengths,
                   "kitti: segment lengths [m] (default the benchmark's 100 200 ... 800)")
        ->check(CLI::PositiveNumber);
    sub.add_option("--step", kitti_.step, "kitti: a segment starts every STEP frames (default 10)")
        ->check(CLI::Range(1, 1000000));
    sub.add_option("--json", json_path_, "also write the results as JSON to this file");
    sub.add_option("--plot", plot_dir_,
                   "write SVG plots (trajectories top view, error over time, error per pair) here");
    sub.add_option("--duplicates", duplicates_,
                   "repeated stamps: error (default), first or last (keep that pose, with a "
                   "warning; --tum defaults to last as the TUM tools, evo's search uses the first)")
        ->check(CLI::IsMember({"error", "first", "last"}));
    sub.add_flag("-q,--quiet", quiet_, "no warnings on stderr");
    sub.footer(
        "Defaults follow evo (no alignment, 0.01 s association, RPE delta 1 frame, consecutive\n"
        "pairs, E = inv(Q_i^-1 Q_j) (P_i^-1 P_j)); --tum follows evaluate_ate.py/evaluate_rpe.py\n"
        "(E = inv(P_j^-1 P_i) (Q_j^-1 Q_i)). KITTI files pair by index unless times are given.\n"
        "\nExamples:\n"
        "  planeslam eval ape groundtruth.txt estimate.txt -a             APE after SE(3) "
        "alignment\n"
        "  planeslam eval ape groundtruth.txt estimate.txt --tum          as evaluate_ate.py\n"
        "  planeslam eval rpe groundtruth.txt estimate.txt -d 10 -u f -r angle_deg\n"
        "  planeslam eval rpe groundtruth.txt estimate.txt --tum --fixed-delta --delta 1 "
        "--delta-unit s\n"
        "  planeslam eval ape 00.txt 00_est.txt --format kitti -as --plot plots/ --json ape.json\n"
        "  planeslam eval kitti poses.txt run/trajectory_kitti.txt     KITTI devkit segment "
        "errors\n"
        "\nkitti: for every 10th first frame and each length L of 100..800 m of the reference's\n"
        "path, E = inv(inv(P_f) P_l) (inv(Q_f) Q_l) over the first frame l beyond L; translation\n"
        "error |t(E)| / L in %, rotation angle(E) / L in deg/100 m, averaged over the segments\n"
        "(as the devkit's evaluate_odometry.cpp); also per length. No alignment.");
  }

  int Run() override {
    const ds::TrajectoryReadOptions read_options = [&] {
      ds::TrajectoryReadOptions o;
      // Real ground truths repeat stamps (TUM fr2/desk has one). An error by default; --tum keeps
      // the last as the TUM tools do (a Python dict); --duplicates chooses explicitly.
      std::string policy = duplicates_;
      if (policy.empty()) policy = tum_ ? "last" : "error";
      o.duplicates = policy == "last"    ? ds::TrajectoryReadOptions::Duplicates::kKeepLast
                     : policy == "first" ? ds::TrajectoryReadOptions::Duplicates::kKeepFirst
                                         : ds::TrajectoryReadOptions::Duplicates::kError;
      o.duplicate_hint = "; --duplicates first|last keeps one";
      return o;
    }();
    ds::TrajectoryReadReport report;
    const ds::TrajectoryFormat ref_format = format_.empty() ? ds::DetectTrajectoryFormat(ref_path_)
                                                            : ds::ParseTrajectoryFormat(format_);
    const ds::TrajectoryFormat est_format = format_.empty() ? ds::DetectTrajectoryFormat(est_path_)
                                                            : ds::ParseTrajectoryFormat(format_);
    const ds::Trajectory ref =
        ds::ReadTrajectory(ref_path_, ref_format, &report, ref_times_, read_options);
    const ds::Trajectory est =
        ds::ReadTrajectory(est_path_, est_format, &report, est_times_, read_options);
    if (!quiet_) {
      for (const std::string& w : report.warnings) std::cerr << "planeslam: warning: " << w << "\n";
    }

    ds::AssociationOptions association;
    const bool by_index = (ref_format == ds::TrajectoryFormat::kKitti && ref_times_.empty()) ||
                          (est_format == ds::TrajectoryFormat::kKitti && est_times_.empty());
    if (by_index) {
      association.method = ds::AssociationOptions::Method::kIndex;
    } else if (tum_) {
      association.method = ds::AssociationOptions::Method::kTum;
      association.max_diff = t_max_diff_opt_->count() > 0 ? t_max_diff_ : 0.02;
    } else {
      association.method = ds::AssociationOptions::Method::kNearest;
      association.max_diff = t_max_diff_opt_->count() > 0 ? t_max_diff_ : 0.01;
    }
    association.offset = t_offset_;

    ds::AlignmentOptions alignment;
    alignment.align = align_ || (tum_ && metric_ == "ape");  // evaluate_ate.py always aligns
    alignment.correct_scale = correct_scale_;
    alignment.align_origin = align_origin_;
    alignment.n_to_align = n_to_align_;
    const ds::PoseRelation relation = ds::ParsePoseRelation(relation_);

    if (metric_ == "kitti") return RunKitti(ref, est, association);
    return metric_ == "ape" ? RunApe(ref, est, association, alignment, relation)
                            : RunRpe(ref, est, association, alignment, relation);
  }

 private:
  std::string AlignmentTitle(const ds::AlignmentOptions& a) const {
    std::string t;
    if (a.align && !a.correct_scale) {
      t = "(with SE(3) Umeyama alignment)";
    } else if (a.align && a.correct_scale) {
      t = "(with Sim(3) Umeyama alignment)";
    } else if (a.correct_scale) {
      t = "(scale corrected)";
    } else if (a.align_origin) {
      t = "(with origin alignment)";
    } else {
      t = "(not aligned)";
    }
    if ((a.align || a.correct_scale) && a.align_origin) t += " (with origin alignment)";
    if ((a.align || a.correct_scale) && a.n_to_align >= 0) {
      t += " (aligned poses: " + std::to_string(a.n_to_align) + ")";
    }
    return t;
  }

  int Fail(const std::string& message) const {
    std::cerr << "planeslam: error: " << message << "\n";
    return 2;
  }

  nlohmann::json CommonJson(const std::string& title, const ds::AlignmentResult& a,
                            const ds::AlignmentOptions& options, ds::PoseRelation relation) const {
    nlohmann::json j;
    j["metric"] = metric_;
    j["semantics"] = tum_ ? "tum" : "evo";
    j["title"] = title;
    j["reference"] = ref_path_;
    j["estimate"] = est_path_;
    j["pose_relation"] = ds::ToString(relation);
    j["unit"] = ds::UnitOf(relation);
    nlohmann::json al;
    al["align"] = options.align;
    al["correct_scale"] = options.correct_scale;
    al["align_origin"] = options.align_origin;
    al["n_to_align"] = options.n_to_align;
    if (a.used_umeyama) {
      const Eigen::Matrix3d& r = a.umeyama.rotation;
      al["rotation"] = {
          {r(0, 0), r(0, 1), r(0, 2)}, {r(1, 0), r(1, 1), r(1, 2)}, {r(2, 0), r(2, 1), r(2, 2)}};
      al["translation"] = {a.umeyama.translation.x(), a.umeyama.translation.y(),
                           a.umeyama.translation.z()};
      al["scale"] = a.umeyama.scale;
    }
    j["alignment"] = al;
    return j;
  }

  void WriteJson(const nlohmann::json& j) const {
    if (json_path_.empty()) return;
    ds::WriteFileAtomic(json_path_, j.dump(2) + "\n");
  }

  int RunApe(const ds::Trajectory& ref, const ds::Trajectory& est,
             const ds::AssociationOptions& association, const ds::AlignmentOptions& alignment,
             ds::PoseRelation relation) {
    ds::ApeOptions options;
    options.association = association;
    options.alignment = alignment;
    options.relation = relation;
    options.scale = scale_;
    const ds::ApeResult r = ds::EvaluateApe(ref, est, options, ref_path_, est_path_);
    if (!r.ok) return Fail(est_path_ + ": " + r.message);

    const std::string unit = ds::UnitOf(relation);
    const std::string title =
        "APE w.r.t. " + ds::Description(relation) + " (" + unit + ")\n" + AlignmentTitle(alignment);
    if (tum_) {
      std::cout << "compared_pose_pairs " << r.stats.count << " pairs\n";
      const std::string name = relation == ds::PoseRelation::kTranslation
                                   ? "absolute_translational_error"
                               : relation == ds::PoseRelation::kRotationAngleDeg ||
                                       relation == ds::PoseRelation::kRotationAngleRad
                                   ? "absolute_rotational_error"
                                   : "absolute_" + ds::ToString(relation) + "_error";
      std::cout << TumStatsBlock(name, r.stats, unit == "unit-less" ? "" : unit);
    } else {
      std::cout << title << "\n\n" << EvoStatsBlock(r.stats);
    }

    nlohmann::json j = CommonJson(title, r.alignment, alignment, relation);
    j.update(StatsJson(r.stats));

    if (!plot_dir_.empty()) {
      EnsureDirectory(plot_dir_);
      const std::string label = "APE (" + unit + ")";
      PlotTrajectories(plot_dir_ + "/ape_trajectories.svg", "APE: trajectories (top view)",
                       r.ref_poses, r.est_poses, r.est_poses, r.errors, label);
      PlotErrorOverTime(plot_dir_ + "/ape_error.svg", "APE over time " + AlignmentTitle(alignment),
                        r.stamps, r.errors, r.stats, label);
    }
    WriteJson(j);
    return 0;
  }

  int RunRpe(const ds::Trajectory& ref, const ds::Trajectory& est,
             const ds::AssociationOptions& association, const ds::AlignmentOptions& alignment,
             ds::PoseRelation relation) {
    ds::RpeOptions options;
    options.association = association;
    options.alignment = alignment;
    options.relation = relation;
    options.delta = delta_;
    options.delta_unit = ds::ParseDeltaUnit(
        delta_unit_opt_->count() > 0 ? delta_unit_ : (tum_ ? std::string("s") : std::string("f")));
    options.all_pairs = all_pairs_;
    options.rel_delta_tol = rel_delta_tol_;
    options.tum = tum_;
    options.fixed_delta = fixed_delta_;
    options.max_pairs = max_pairs_;
    options.scale = scale_;
    options.seed = seed_;
    const ds::RpeResult r = ds::EvaluateRpe(ref, est, options, ref_path_, est_path_);
    if (!r.ok) return Fail(est_path_ + ": " + r.message);

    const std::string unit = ds::UnitOf(relation);
    const std::string delta_text =
        options.delta_unit == ds::DeltaUnit::kFrames
            ? std::to_string(static_cast<long long>(std::llround(options.delta)))
            : PyFloat(options.delta);
    std::string title = "RPE w.r.t. " + ds::Description(relation) + " (" + unit +
                        ")\nfor delta = " + delta_text + " (" + ds::ToString(options.delta_unit) +
                        ")";
    if (tum_) {
      title += fixed_delta_ ? " using fixed-delta pairs (TUM evaluate_rpe.py)"
                            : " using all or random pairs (TUM evaluate_rpe.py)";
    } else {
      title += all_pairs_ ? " using all pairs" : " using consecutive pairs";
    }
    title += "\n" + AlignmentTitle(alignment);

    if (tum_) {
      std::cout << "compared_pose_pairs " << r.trans_stats.count << " pairs\n"
                << TumStatsBlock("translational_error", r.trans_stats, "m")
                << TumStatsBlock("rotational_error", r.rot_stats_deg, "deg");
    } else {
      std::cout << title << "\n\n" << EvoStatsBlock(r.stats);
    }

    nlohmann::json j = CommonJson(title, r.alignment, alignment, relation);
    j.update(StatsJson(r.stats));
    j["delta"] = options.delta;
    j["delta_unit"] = ds::ToString(options.delta_unit);
    j["all_pairs"] = all_pairs_;
    j["fixed_delta"] = fixed_delta_;
    j["translation"] = StatsJson(r.trans_stats);
    j["rotation_deg"] = StatsJson(r.rot_stats_deg);

    if (!plot_dir_.empty()) {
      EnsureDirectory(plot_dir_);
      const std::string label = "RPE (" + unit + ")";
      std::vector<Pose> ends;
      for (const ds::IndexPair& p : r.est_pairs) ends.push_back(r.est_poses[p.second]);
      PlotTrajectories(plot_dir_ + "/rpe_trajectories.svg",
                       "RPE: trajectories (top view), error at the pairs' second pose", r.ref_poses,
                       r.est_poses, ends, r.errors, label);
      PlotErrorOverTime(plot_dir_ + "/rpe_error.svg", "RPE over time", r.stamps, r.errors, r.stats,
                        label);
      std::vector<double> index(r.errors.size());
      for (std::size_t i = 0; i < index.size(); ++i) index[i] = static_cast<double>(i);
      SvgPlot per_pair(
          "RPE per pair (delta = " + delta_text + " " + ds::ToString(options.delta_unit) + ")",
          "pair index", label);
      LineStyle thin;
      thin.width = 0.8;
      thin.color = SvgColor{170, 170, 170};
      per_pair.AddLine(index, r.errors, thin);
      per_pair.AddScatter(index, r.errors, CycleColor(0), "error per pair", 2.0);
      AddStatLines(per_pair, r.stats);
      per_pair.Write(plot_dir_ + "/rpe_pairs.svg");
    }
    WriteJson(j);
    return 0;
  }

  int RunKitti(const ds::Trajectory& ref, const ds::Trajectory& est,
               const ds::AssociationOptions& association) {
    const std::vector<ds::IndexPair> pairs =
        ds::AssociateTrajectories(ref, est, association, ref_path_, est_path_);
    std::vector<Pose> gt, es;
    for (const auto& [i, j] : pairs) {
      gt.push_back(ref.poses[i]);
      es.push_back(est.poses[j]);
    }
    const ds::KittiOdometryResult r = ds::EvaluateKittiOdometry(gt, es, kitti_);
    if (!r.ok) return Fail(ref_path_ + ": " + r.message);
    std::cout << FormatKittiErrors(r, pairs.size());
    nlohmann::json j = KittiErrorsJson(r);
    j["metric"] = "kitti";
    j["reference"] = ref_path_;
    j["estimate"] = est_path_;
    j["pairs"] = pairs.size();
    j["step"] = kitti_.step;
    if (!plot_dir_.empty()) {
      EnsureDirectory(plot_dir_);
      std::vector<double> lengths, t_err, r_err;
      for (const ds::KittiLengthErrors& l : r.per_length) {
        lengths.push_back(l.length);
        t_err.push_back(100.0 * l.t_err);
        r_err.push_back(l.r_err * 180.0 / kPi * 100.0);
      }
      LineStyle style;
      style.color = CycleColor(0);
      SvgPlot t_plot("KITTI translation error per segment length", "segment length [m]",
                     "translation error [%]");
      t_plot.AddLine(lengths, t_err, style);
      t_plot.AddScatter(lengths, t_err, CycleColor(0), "mean over the segments", 3.0);
      t_plot.Write(plot_dir_ + "/kitti_translation.svg");
      SvgPlot r_plot("KITTI rotation error per segment length", "segment length [m]",
                     "rotation error [deg/100 m]");
      r_plot.AddLine(lengths, r_err, style);
      r_plot.AddScatter(lengths, r_err, CycleColor(0), "mean over the segments", 3.0);
      r_plot.Write(plot_dir_ + "/kitti_rotation.svg");
    }
    WriteJson(j);
    return kExitSuccess;
  }

  ds::KittiOdometryOptions kitti_;
  std::string metric_, ref_path_, est_path_, format_, ref_times_, est_times_;
  bool tum_ = false, align_ = false, correct_scale_ = false, align_origin_ = false;
  double t_max_diff_ = 0.01, t_offset_ = 0.0;
  CLI::Option* t_max_diff_opt_ = nullptr;
  CLI::Option* delta_unit_opt_ = nullptr;
  int n_to_align_ = -1;
  std::string relation_ = "trans_part";
  double delta_ = 1.0;
  std::string delta_unit_ = "f";
  bool all_pairs_ = false;
  double rel_delta_tol_ = 0.1;
  bool fixed_delta_ = false;
  std::size_t max_pairs_ = 10000;
  double scale_ = 1.0;
  std::uint32_t seed_ = 0;
  std::string json_path_, plot_dir_, duplicates_;
  bool quiet_ = false;
};

PLANESLAM_REGISTER_COMMAND(EvalCommand);

}  // namespace
}  // namespace planeslam::app
