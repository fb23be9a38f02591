// planeslam.eval.ape / rpe: trajectory metrics with the semantics and defaults of `planeslam eval`
// (evo's, or the TUM RGB-D tools' with tum=True), on files or (N, 8) arrays.
#include <pybind11/stl.h>

#include <cmath>
#include <string>

#include "planeslam/datasets/trajectory_eval.hpp"
#include "planeslam/datasets/trajectory_io.hpp"
#include "py_common.hpp"

namespace planeslam::python {
namespace {

namespace ds = planeslam::datasets;

/// A trajectory argument and how the results name it.
struct Input {
  ds::Trajectory trajectory;
  std::string name;
  bool kitti_by_index = false;  ///< a KITTI file without times: paired by index
};

/// An (N, 8) array `t tx ty tz qx qy qz qw`, checked as the TUM reader checks a file's lines.
ds::Trajectory ArrayTrajectory(const py::handle& handle, const std::string& what) {
  const auto a = py::array_t<double, py::array::forcecast>::ensure(handle);
  if (!a || a.ndim() != 2 || a.shape(1) != 8 || a.shape(0) < 1) {
    throw std::invalid_argument(what + ": expected an (N, 8) array of t tx ty tz qx qy qz qw");
  }
  const auto m = a.unchecked<2>();
  ds::Trajectory t;
  for (py::ssize_t i = 0; i < a.shape(0); ++i) {
    const std::string row = what + ": row " + std::to_string(i) + ": ";
    for (int c = 0; c < 8; ++c) {
      if (!std::isfinite(m(i, c))) throw std::invalid_argument(row + "NaN or inf");
    }
    if (!t.empty() && !(m(i, 0) > t.stamps.back())) {
      throw std::invalid_argument(row + "stamp " + ds::FormatRoundTrip(m(i, 0)) +
                                  " is not after the previous one");
    }
    Eigen::Quaterniond q(m(i, 7), m(i, 4), m(i, 5), m(i, 6));
    if (!(std::abs(q.norm() - 1.0) <= ds::TrajectoryReadOptions().max_tolerance)) {
      throw std::invalid_argument(row + "quaternion norm " + std::to_string(q.norm()) +
                                  " is not 1");
    }
    q.normalize();
    Pose pose = Pose::Identity();
    pose.linear() = q.toRotationMatrix();
    pose.translation() = Eigen::Vector3d(m(i, 1), m(i, 2), m(i, 3));
    t.Add(m(i, 0), pose);
  }
  return t;
}

/// A file path (format detected or `format`) or an array.
Input ReadInput(const py::handle& src, const std::string& what, const std::string& format,
                const py::object& times, const std::string& duplicates) {
  Input in;
  if (py::isinstance<py::str>(src) || py::hasattr(src, "__fspath__")) {
    in.name = py::str(py::module_::import("os").attr("fspath")(src)).cast<std::string>();
    const ds::TrajectoryFormat f = format.empty() ? ds::DetectTrajectoryFormat(in.name)
                                                  : ds::ParseTrajectoryFormat(format);
    ds::TrajectoryReadOptions o;
    o.duplicates = duplicates == "last"    ? ds::TrajectoryReadOptions::Duplicates::kKeepLast
                   : duplicates == "first" ? ds::TrajectoryReadOptions::Duplicates::kKeepFirst
                                           : ds::TrajectoryReadOptions::Duplicates::kError;
    const std::string times_path =
        times.is_none() ? std::string()
                        : py::str(py::module_::import("os").attr("fspath")(times)).cast<std::string>();
    in.trajectory = ds::ReadTrajectory(in.name, f, nullptr, times_path, o);
    in.kitti_by_index = f == ds::TrajectoryFormat::kKitti && times_path.empty();
  } else {
    in.name = what + " array";
    in.trajectory = ArrayTrajectory(src, what);
  }
  return in;
}

/// The options every metric shares, as `planeslam eval` sets them.
struct Common {
  bool tum = false;
  ds::AssociationOptions association;
  ds::AlignmentOptions alignment;
  ds::PoseRelation relation = ds::PoseRelation::kTranslation;
};

Common MakeCommon(const Input& ref, const Input& est, bool tum, const py::object& t_max_diff,
                  double t_offset, const ds::AlignmentOptions& alignment,
                  const std::string& relation) {
  Common c;
  c.tum = tum;
  if (ref.kitti_by_index || est.kitti_by_index) {
    c.association.method = ds::AssociationOptions::Method::kIndex;
  } else {
    c.association.method =
        tum ? ds::AssociationOptions::Method::kTum : ds::AssociationOptions::Method::kNearest;
    c.association.max_diff = t_max_diff.is_none() ? (tum ? 0.02 : 0.01) : t_max_diff.cast<double>();
  }
  c.association.offset = t_offset;
  c.alignment = alignment;
  c.relation = ds::ParsePoseRelation(relation);
  return c;
}

std::string AlignmentTitle(const ds::AlignmentOptions& a) {
  std::string t = a.align && !a.correct_scale ? "(with SE(3) Umeyama alignment)"
                  : a.align                   ? "(with Sim(3) Umeyama alignment)"
                  : a.correct_scale           ? "(scale corrected)"
                  : a.align_origin            ? "(with origin alignment)"
                                              : "(not aligned)";
  if ((a.align || a.correct_scale) && a.align_origin) t += " (with origin alignment)";
  if ((a.align || a.correct_scale) && a.n_to_align >= 0) {
    t += " (aligned poses: " + std::to_string(a.n_to_align) + ")";
  }
  return t;
}

py::dict Stats(const ds::ErrorStatistics& s) {
  py::dict d;
  d["rmse"] = s.rmse;
  d["mean"] = s.mean;
  d["median"] = s.median;
  d["std"] = s.std;
  d["min"] = s.min;
  d["max"] = s.max;
  d["sse"] = s.sse;
  d["pairs"] = s.count;
  return d;
}

/// The keys of `planeslam eval --json` before the statistics.
py::dict Header(const std::string& metric, const std::string& title, const Input& ref,
                const Input& est, const Common& c, const ds::AlignmentResult& a) {
  py::dict j;
  j["metric"] = metric;
  j["semantics"] = c.tum ? "tum" : "evo";
  j["title"] = title;
  j["reference"] = ref.name;
  j["estimate"] = est.name;
  j["pose_relation"] = ds::ToString(c.relation);
  j["unit"] = ds::UnitOf(c.relation);
  py::dict al;
  al["align"] = c.alignment.align;
  al["correct_scale"] = c.alignment.correct_scale;
  al["align_origin"] = c.alignment.align_origin;
  al["n_to_align"] = c.alignment.n_to_align;
  if (a.used_umeyama) {
    Eigen::Matrix<double, 3, 3, Eigen::RowMajor> r = a.umeyama.rotation;
    al["rotation"] = py::array_t<double>({3, 3}, r.data());
    const Eigen::Vector3d& t = a.umeyama.translation;
    al["translation"] = py::array_t<double>(3, t.data());
    al["scale"] = a.umeyama.scale;
  }
  j["alignment"] = al;
  return j;
}

py::dict Ape(const py::handle& ref_src, const py::handle& est_src, bool align, bool correct_scale,
             bool align_origin, int n_to_align, const std::string& pose_relation, bool tum,
             const py::object& t_max_diff, double t_offset, double scale,
             const std::string& format, const py::object& ref_times, const py::object& est_times,
             const py::object& duplicates) {
  const std::string dup = duplicates.is_none() ? (tum ? "last" : "error")
                                               : duplicates.cast<std::string>();
  const Input ref = ReadInput(ref_src, "ref", format, ref_times, dup);
  const Input est = ReadInput(est_src, "est", format, est_times, dup);
  ds::AlignmentOptions al;
  al.align = align || tum;  // evaluate_ate.py always aligns
  al.correct_scale = correct_scale;
  al.align_origin = align_origin;
  al.n_to_align = n_to_align;
  const Common c = MakeCommon(ref, est, tum, t_max_diff, t_offset, al, pose_relation);
  ds::ApeOptions options;
  options.association = c.association;
  options.alignment = c.alignment;
  options.relation = c.relation;
  options.scale = scale;
  ds::ApeResult r;
  {
    py::gil_scoped_release release;
    r = ds::EvaluateApe(ref.trajectory, est.trajectory, options, ref.name, est.name);
  }
  if (!r.ok) throw std::invalid_argument(est.name + ": " + r.message);
  const std::string title = "APE w.r.t. " + ds::Description(c.relation) + " (" +
                            ds::UnitOf(c.relation) + ")\n" + AlignmentTitle(c.alignment);
  py::dict j = Header("ape", title, ref, est, c, r.alignment);
  for (const auto& [k, v] : Stats(r.stats)) j[k] = v;
  j["errors"] = py::array_t<double>(r.errors.size(), r.errors.data());
  j["stamps"] = py::array_t<double>(r.stamps.size(), r.stamps.data());
  return j;
}

py::dict Rpe(const py::handle& ref_src, const py::handle& est_src, double delta,
             const py::object& delta_unit, const std::string& pose_relation, bool all_pairs,
             double rel_delta_tol, bool align, bool correct_scale, bool align_origin,
             int n_to_align, bool tum, bool fixed_delta, std::size_t max_pairs, double scale,
             std::uint32_t seed, const py::object& t_max_diff, double t_offset,
             const std::string& format, const py::object& ref_times, const py::object& est_times,
             const py::object& duplicates) {
  const std::string dup = duplicates.is_none() ? (tum ? "last" : "error")
                                               : duplicates.cast<std::string>();
  const Input ref = ReadInput(ref_src, "ref", format, ref_times, dup);
  const Input est = ReadInput(est_src, "est", format, est_times, dup);
  ds::AlignmentOptions al;
  al.align = align;
  al.correct_scale = correct_scale;
  al.align_origin = align_origin;
  al.n_to_align = n_to_align;
  const Common c = MakeCommon(ref, est, tum, t_max_diff, t_offset, al, pose_relation);
  ds::RpeOptions o;
  o.association = c.association;
  o.alignment = c.alignment;
  o.relation = c.relation;
  o.delta = delta;
  o.delta_unit = ds::ParseDeltaUnit(delta_unit.is_none() ? std::string(tum ? "s" : "f")
                                                         : delta_unit.cast<std::string>());
  o.all_pairs = all_pairs;
  o.rel_delta_tol = rel_delta_tol;
  o.tum = tum;
  o.fixed_delta = fixed_delta;
  o.max_pairs = max_pairs;
  o.scale = scale;
  o.seed = seed;
  ds::RpeResult r;
  {
    py::gil_scoped_release release;
    r = ds::EvaluateRpe(ref.trajectory, est.trajectory, o, ref.name, est.name);
  }
  if (!r.ok) throw std::invalid_argument(est.name + ": " + r.message);
  const std::string delta_text =
      o.delta_unit == ds::DeltaUnit::kFrames
          ? std::to_string(static_cast<long long>(std::llround(o.delta)))
          : py::repr(py::float_(o.delta)).cast<std::string>();
  std::string title = "RPE w.r.t. " + ds::Description(c.relation) + " (" +
                      ds::UnitOf(c.relation) + ")\nfor delta = " + delta_text + " (" +
                      ds::ToString(o.delta_unit) + ")";
  if (tum) {
    title += fixed_delta ? " using fixed-delta pairs (TUM evaluate_rpe.py)"
                         : " using all or random pairs (TUM evaluate_rpe.py)";
  } else {
    title += all_pairs ? " using all pairs" : " using consecutive pairs";
  }
  title += "\n" + AlignmentTitle(c.alignment);
  py::dict j = Header("rpe", title, ref, est, c, r.alignment);
  for (const auto& [k, v] : Stats(r.stats)) j[k] = v;
  j["delta"] = o.delta;
  j["delta_unit"] = ds::ToString(o.delta_unit);
  j["all_pairs"] = all_pairs;
  j["fixed_delta"] = fixed_delta;
  j["translation"] = Stats(r.trans_stats);
  j["rotation_deg"] = Stats(r.rot_stats_deg);
  j["errors"] = py::array_t<double>(r.errors.size(), r.errors.data());
  j["stamps"] = py::array_t<double>(r.stamps.size(), r.stamps.data());
  return j;
}

}  // namespace

void RegisterEval(py::module_& m) {
  py::module_ e = m.def_submodule("_eval", "Trajectory metrics (planeslam.eval).");
  e.def("ape", &Ape, py::arg("ref"), py::arg("est"), py::arg("align") = true,
        py::arg("correct_scale") = false, py::arg("align_origin") = false,
        py::arg("n_to_align") = -1, py::arg("pose_relation") = "trans_part",
        py::arg("tum") = false, py::arg("t_max_diff") = py::none(), py::arg("t_offset") = 0.0,
        py::arg("scale") = 1.0, py::arg("format") = "", py::arg("ref_times") = py::none(),
        py::arg("est_times") = py::none(), py::arg("duplicates") = py::none(),
        R"doc(Absolute pose error, as `planeslam eval ape` (evo's semantics; tum=True: evaluate_ate.py).

ref, est: trajectory files (TUM, KITTI or EuRoC, detected or given by format) or (N, 8) arrays
    t tx ty tz qx qy qz qw (stamps increasing).
align: SE(3) Umeyama alignment (evo -a); correct_scale: Sim(3) with align, scale only without;
align_origin, n_to_align, pose_relation (trans_part, angle_deg, angle_rad, rot_part, full),
t_max_diff [s] (evo 0.01, tum 0.02), t_offset [s], scale, ref_times/est_times (KITTI times
files), duplicates (error, first, last): as the CLI options of the same names.

Returns the dict `planeslam eval ape --json` writes (rmse, mean, median, std, min, max, sse,
pairs, title, alignment, ...) plus 'errors' and 'stamps' per pair. Raises OSError on an
unreadable file, ValueError on bad arrays, options or a degenerate alignment.)doc");
  e.def("rpe", &Rpe, py::arg("ref"), py::arg("est"), py::arg("delta") = 1.0,
        py::arg("delta_unit") = py::none(), py::arg("pose_relation") = "trans_part",
        py::arg("all_pairs") = false, py::arg("rel_delta_tol") = 0.1, py::arg("align") = false,
        py::arg("correct_scale") = false, py::arg("align_origin") = false,
        py::arg("n_to_align") = -1, py::arg("tum") = false, py::arg("fixed_delta") = false,
        py::arg("max_pairs") = 10000, py::arg("scale") = 1.0, py::arg("seed") = 0,
        py::arg("t_max_diff") = py::none(), py::arg("t_offset") = 0.0, py::arg("format") = "",
        py::arg("ref_times") = py::none(), py::arg("est_times") = py::none(),
        py::arg("duplicates") = py::none(),
        R"doc(Relative pose error, as `planeslam eval rpe` (evo's semantics; tum=True: evaluate_rpe.py).

delta, delta_unit (f, m, deg, rad; s with tum; default f, with tum s), all_pairs,
rel_delta_tol, fixed_delta, max_pairs, seed: as the CLI options of the same names; the others
as in ape() (alignment off by default, as the CLI).

Returns the dict `planeslam eval rpe --json` writes (statistics of pose_relation, 'translation'
and 'rotation_deg' statistics, delta, ...) plus 'errors' and 'stamps' per pair.)doc");
}

}  // namespace planeslam::python
