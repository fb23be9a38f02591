#include "planeslam/datasets/trajectory_eval.hpp"

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <numeric>
#include <random>
#include <sstream>
#include <tuple>

#include "planeslam/datasets/errors.hpp"

namespace planeslam::datasets {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kRadToDeg = 180.0 / kPi;

/// Index of the first minimum of |values[k] - target| over a sorted `values` (numpy's argmin of
/// the absolute differences, which evo uses), in O(log n).
std::size_t NearestIndex(const std::vector<double>& values, double target) {
  // For sorted values the nearest is one of the two around target's insertion point.
  const std::size_t n = values.size();
  const std::size_t k = static_cast<std::size_t>(
      std::lower_bound(values.begin(), values.end(), target) - values.begin());
  std::size_t best = 0;
  if (k == n) {
    best = n - 1;
  } else if (k > 0) {
    best = std::abs(values[k - 1] - target) <= std::abs(values[k] - target) ? k - 1 : k;
  }
  while (best > 0 && values[best - 1] == values[best]) --best;  // argmin: first minimum
  return best;
}

double Median(std::vector<double> values) {
  if (values.empty()) return 0.0;
  std::sort(values.begin(), values.end());
  const std::size_t n = values.size();
  return n % 2 == 1 ? values[n / 2] : 0.5 * (values[n / 2 - 1] + values[n / 2]);
}

std::string FormatNumber(double value) {
  std::ostringstream os;
  os << value;
  return os.str();
}

Eigen::Matrix3Xd Positions(const std::vector<Pose>& poses, std::size_t count) {
  Eigen::Matrix3Xd m(3, static_cast<Eigen::Index>(count));
  for (std::size_t i = 0; i < count; ++i)
    m.col(static_cast<Eigen::Index>(i)) = poses[i].translation();
  return m;
}

/// numpy.linalg.inv of a 4x4 transform (the TUM tool's ominus uses a general inverse).
Eigen::Matrix4d Inverse(const Eigen::Matrix4d& m) { return m.inverse(); }

void FillBothParts(const std::vector<Pose>& error_poses, RpeResult& result) {
  result.trans_errors.clear();
  result.rot_errors_deg.clear();
  for (const Pose& e : error_poses) {
    result.trans_errors.push_back(e.translation().norm());
    result.rot_errors_deg.push_back(RotationAngle(e.linear()) * kRadToDeg);
  }
  result.trans_stats = ComputeStatistics(result.trans_errors);
  result.rot_stats_deg = ComputeStatistics(result.rot_errors_deg);
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Association

std::vector<IndexPair> AssociateNearest(const std::vector<double>& ref_stamps,
                                        const std::vector<double>& est_stamps, double max_diff,
                                        double offset) {
  std::vector<IndexPair> pairs;
  if (ref_stamps.empty() || est_stamps.empty()) return pairs;
  // evo: the estimate (traj_2) is the "long" one only when strictly longer; the offset moves the
  // long trajectory's stamps (+offset when that is the estimate, -offset when the reference), and
  // the difference is |long_shifted - short|, computed in that order for the same rounding.
  const bool est_longer = est_stamps.size() > ref_stamps.size();
  const std::vector<double>& long_stamps = est_longer ? est_stamps : ref_stamps;
  const std::vector<double>& short_stamps = est_longer ? ref_stamps : est_stamps;
  std::vector<double> shifted(long_stamps.size());
  const double shift = est_longer ? offset : -offset;
  for (std::size_t i = 0; i < long_stamps.size(); ++i) shifted[i] = long_stamps[i] + shift;
  for (std::size_t s = 0; s < short_stamps.size(); ++s) {
    const std::size_t l = NearestIndex(shifted, short_stamps[s]);
    if (std::abs(shifted[l] - short_stamps[s]) <= max_diff) {
      pairs.push_back(est_longer ? IndexPair{s, l} : IndexPair{l, s});
    }
  }
  return pairs;
}

std::vector<IndexPair> AssociateTum(const std::vector<double>& ref_stamps,
                                    const std::vector<double>& est_stamps, double max_diff,
                                    double offset) {
  // associate.py: potential_matches = [(abs(a - (b + offset)), a, b) ... if < max_difference],
  // sorted (by difference, then a, then b), taken greedily one to one, then sorted by (a, b).
  struct Candidate {
    double diff;
    double a, b;
    std::size_t ia, ib;
  };
  std::vector<Candidate> candidates;
  for (std::size_t ib = 0; ib < est_stamps.size(); ++ib) {
    const double b = est_stamps[ib] + offset;
    // Window search with a margin; the exact test below decides.
    const double margin = 2.0 * max_diff + 1e-9 * std::abs(b);
    auto it = std::lower_bound(ref_stamps.begin(), ref_stamps.end(), b - margin);
    for (; it != ref_stamps.end() && *it <= b + margin; ++it) {
      const double diff = std::abs(*it - b);
      if (diff < max_diff) {
        candidates.push_back(
            {diff, *it, est_stamps[ib], static_cast<std::size_t>(it - ref_stamps.begin()), ib});
      }
    }
  }
  std::sort(candidates.begin(), candidates.end(), [](const Candidate& x, const Candidate& y) {
    return std::tie(x.diff, x.a, x.b) < std::tie(y.diff, y.a, y.b);
  });
  std::vector<char> used_ref(ref_stamps.size(), 0), used_est(est_stamps.size(), 0);
  std::vector<IndexPair> pairs;
  for (const Candidate& c : candidates) {
    if (used_ref[c.ia] || used_est[c.ib]) continue;
    used_ref[c.ia] = used_est[c.ib] = 1;
    pairs.emplace_back(c.ia, c.ib);
  }
  std::sort(pairs.begin(), pairs.end());
  return pairs;
}

std::vector<IndexPair> AssociateByIndex(std::size_t n_ref, std::size_t n_est) {
  std::vector<IndexPair> pairs;
  for (std::size_t i = 0; i < std::min(n_ref, n_est); ++i) pairs.emplace_back(i, i);
  return pairs;
}

std::vector<IndexPair> AssociateTrajectories(const Trajectory& ref, const Trajectory& est,
                                             const AssociationOptions& options,
                                             const std::string& ref_name,
                                             const std::string& est_name) {
  std::vector<IndexPair> pairs;
  switch (options.method) {
    case AssociationOptions::Method::kIndex:
      if (ref.size() != est.size()) {
        throw IoError(est_name, "has " + std::to_string(est.size()) + " poses but " + ref_name +
                                    " has " + std::to_string(ref.size()) +
                                    " (files without stamps pair by index: give a times file)");
      }
      return AssociateByIndex(ref.size(), est.size());
    case AssociationOptions::Method::kNearest:
      pairs = AssociateNearest(ref.stamps, est.stamps, options.max_diff, options.offset);
      break;
    case AssociationOptions::Method::kTum:
      pairs = AssociateTum(ref.stamps, est.stamps, options.max_diff, options.offset);
      break;
  }
  if (pairs.empty()) {
    std::ostringstream os;
    os.precision(15);
    os << "no timestamps within " << options.max_diff << " s of " << ref_name << " (estimate "
       << "covers [" << (est.empty() ? 0.0 : est.stamps.front()) << ", "
       << (est.empty() ? 0.0 : est.stamps.back()) << "] s, reference ["
       << (ref.empty() ? 0.0 : ref.stamps.front()) << ", "
       << (ref.empty() ? 0.0 : ref.stamps.back()) << "] s, offset " << options.offset
       << " s); check --t-offset / --t-max-diff";
    throw IoError(est_name, os.str());
  }
  return pairs;
}

// ---------------------------------------------------------------------------------------------
// Alignment

UmeyamaResult UmeyamaAlignment(const Eigen::Matrix3Xd& source, const Eigen::Matrix3Xd& target,
                               bool with_scale) {
  PLANESLAM_CHECK(source.cols() == target.cols(), "point sets differ in size");
  UmeyamaResult result;
  const Eigen::Index n = source.cols();
  if (n < 3) {
    result.degenerate = true;
    result.reason = "alignment needs at least 3 poses, got " + std::to_string(n);
    return result;
  }
  const double inv_n = 1.0 / static_cast<double>(n);
  const Eigen::Vector3d mean_x = source.rowwise().sum() * inv_n;  // eq. 34
  const Eigen::Vector3d mean_y = target.rowwise().sum() * inv_n;  // eq. 35
  const Eigen::Matrix3Xd xc = source.colwise() - mean_x;
  const Eigen::Matrix3Xd yc = target.colwise() - mean_y;
  const double sigma_x = xc.squaredNorm() * inv_n;          // eq. 36
  const Eigen::Matrix3d cov = yc * xc.transpose() * inv_n;  // eq. 38
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(cov, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Vector3d d = svd.singularValues();
  result.singular_values = d;
  // Rank < 2 leaves the rotation about the line (or everything) free. evo tests d > machine eps
  // in absolute terms; a relative test does not depend on the trajectory's units.
  if (!(d(0) > 0.0) || d(1) <= 1e-12 * d(0)) {
    result.degenerate = true;
    result.reason =
        "degenerate geometry for alignment: the positions are collinear or coincident "
        "(cross-covariance rank < 2)";
    return result;
  }
  Eigen::Matrix3d s = Eigen::Matrix3d::Identity();  // eq. 43: keep a proper rotation
  if (svd.matrixU().determinant() * svd.matrixV().determinant() < 0.0) s(2, 2) = -1.0;
  result.transform.rotation = svd.matrixU() * s * svd.matrixV().transpose();           // eq. 40
  result.transform.scale = with_scale ? (d.asDiagonal() * s).trace() / sigma_x : 1.0;  // eq. 42
  result.transform.translation =
      mean_y - result.transform.scale * result.transform.rotation * mean_x;  // eq. 41
  return result;
}

AlignmentResult AlignTrajectory(const std::vector<Pose>& ref, std::vector<Pose>& est,
                                const AlignmentOptions& options) {
  PLANESLAM_CHECK(ref.size() == est.size(), "associated trajectories differ in length");
  AlignmentResult result;
  if (options.align || options.correct_scale) {
    std::size_t n = est.size();
    if (options.n_to_align >= 0) n = std::min(n, static_cast<std::size_t>(options.n_to_align));
    const UmeyamaResult fit =
        UmeyamaAlignment(Positions(est, n), Positions(ref, n), options.correct_scale);
    if (fit.degenerate) {
      result.degenerate = true;
      result.reason = fit.reason;
      return result;
    }
    result.used_umeyama = true;
    result.umeyama = fit.transform;
    const bool only_scale = options.correct_scale && !options.align;
    if (only_scale) {  // evo -s: the scale of the Sim(3) fit, applied about the origin
      result.umeyama.rotation.setIdentity();
      result.umeyama.translation.setZero();
    }
    for (Pose& pose : est) {
      pose.translation() *= result.umeyama.scale;
      if (!only_scale) {
        Pose t = Pose::Identity();
        t.linear() = result.umeyama.rotation;
        t.translation() = result.umeyama.translation;
        pose = t * pose;
      }
    }
  }
  if (options.align_origin && !est.empty()) {
    result.used_origin = true;
    result.origin = ref.front() * est.front().inverse();
    for (Pose& pose : est) pose = result.origin * pose;
  }
  return result;
}

// ---------------------------------------------------------------------------------------------
// Errors and statistics

std::string ToString(PoseRelation relation) {
  switch (relation) {
    case PoseRelation::kTranslation:
      return "trans_part";
    case PoseRelation::kRotationAngleDeg:
      return "angle_deg";
    case PoseRelation::kRotationAngleRad:
      return "angle_rad";
    case PoseRelation::kRotationPart:
      return "rot_part";
    case PoseRelation::kFull:
      return "full";
  }
  return "?";
}

PoseRelation ParsePoseRelation(const std::string& name) {
  for (PoseRelation r :
       {PoseRelation::kTranslation, PoseRelation::kRotationAngleDeg,
        PoseRelation::kRotationAngleRad, PoseRelation::kRotationPart, PoseRelation::kFull}) {
    if (ToString(r) == name) return r;
  }
  throw ConfigError("unknown pose relation '" + name +
                    "' (expected trans_part, angle_deg, angle_rad, rot_part or full)");
}

std::string Description(PoseRelation relation) {
  switch (relation) {
    case PoseRelation::kTranslation:
      return "translation part";
    case PoseRelation::kRotationAngleDeg:
      return "rotation angle in degrees";
    case PoseRelation::kRotationAngleRad:
      return "rotation angle in radians";
    case PoseRelation::kRotationPart:
      return "rotation part";
    case PoseRelation::kFull:
      return "full transformation";
  }
  return "?";
}

std::string UnitOf(PoseRelation relation) {
  switch (relation) {
    case PoseRelation::kTranslation:
      return "m";
    case PoseRelation::kRotationAngleDeg:
      return "deg";
    case PoseRelation::kRotationAngleRad:
      return "rad";
    default:
      return "unit-less";
  }
}

double RotationAngle(const Eigen::Matrix3d& r) {
  const Eigen::Vector3d v(r(2, 1) - r(1, 2), r(0, 2) - r(2, 0), r(1, 0) - r(0, 1));
  return std::atan2(v.norm(), r.trace() - 1.0);  // 2 sin(θ) and 2 cos(θ)
}

double ErrorOf(const Pose& e, PoseRelation relation) {
  switch (relation) {
    case PoseRelation::kTranslation:
      return e.translation().norm();
    case PoseRelation::kRotationAngleDeg:
      return RotationAngle(e.linear()) * kRadToDeg;
    case PoseRelation::kRotationAngleRad:
      return RotationAngle(e.linear());
    case PoseRelation::kRotationPart:
      return (e.linear() - Eigen::Matrix3d::Identity()).norm();
    case PoseRelation::kFull:
      return (e.matrix() - Eigen::Matrix4d::Identity()).norm();
  }
  return 0.0;
}

ErrorStatistics ComputeStatistics(const std::vector<double>& errors) {
  ErrorStatistics s;
  s.count = errors.size();
  if (errors.empty()) return s;
  const double n = static_cast<double>(errors.size());
  double sum = 0.0;
  for (double e : errors) {
    sum += e;
    s.sse += e * e;
  }
  s.mean = sum / n;
  s.rmse = std::sqrt(s.sse / n);
  double var = 0.0;
  for (double e : errors) var += (e - s.mean) * (e - s.mean);
  s.std = std::sqrt(var / n);  // numpy.std: population (ddof 0)
  s.median = Median(errors);
  const auto [lo, hi] = std::minmax_element(errors.begin(), errors.end());
  s.min = *lo;
  s.max = *hi;
  return s;
}

std::vector<double> ApeErrors(const std::vector<Pose>& ref, const std::vector<Pose>& est,
                              PoseRelation relation) {
  PLANESLAM_CHECK(ref.size() == est.size(), "associated trajectories differ in length");
  std::vector<double> errors;
  errors.reserve(ref.size());
  for (std::size_t i = 0; i < ref.size(); ++i) {
    if (relation == PoseRelation::kTranslation) {
      errors.push_back((est[i].translation() - ref[i].translation()).norm());
    } else {
      errors.push_back(ErrorOf(est[i].inverse() * ref[i], relation));  // evo: ape_base(est, ref)
    }
  }
  return errors;
}

DeltaUnit ParseDeltaUnit(const std::string& name) {
  if (name == "f" || name == "frames") return DeltaUnit::kFrames;
  if (name == "m") return DeltaUnit::kMeters;
  if (name == "deg") return DeltaUnit::kDegrees;
  if (name == "rad") return DeltaUnit::kRadians;
  if (name == "s") return DeltaUnit::kSeconds;
  throw ConfigError("unknown delta unit '" + name + "' (expected f, m, deg, rad or s)");
}

std::string ToString(DeltaUnit unit) {
  switch (unit) {
    case DeltaUnit::kFrames:
      return "frames";
    case DeltaUnit::kMeters:
      return "m";
    case DeltaUnit::kDegrees:
      return "deg";
    case DeltaUnit::kRadians:
      return "rad";
    case DeltaUnit::kSeconds:
      return "s";
  }
  return "?";
}

std::vector<IndexPair> EvoRpePairs(const std::vector<Pose>& poses, double delta, DeltaUnit unit,
                                   double rel_tol, bool all_pairs) {
  std::vector<IndexPair> pairs;
  const std::size_t n = poses.size();
  if (n == 0) return pairs;
  const double tol = delta * rel_tol;
  if (unit == DeltaUnit::kFrames) {  // filters.filter_pairs_by_index
    const auto step = static_cast<std::size_t>(std::llround(delta));
    if (step == 0) return pairs;
    if (all_pairs) {
      for (std::size_t i = 0; i + step < n; ++i) pairs.emplace_back(i, i + step);
    } else {
      for (std::size_t i = 0; i + step < n; i += step) pairs.emplace_back(i, i + step);
    }
  } else if (unit == DeltaUnit::kMeters) {  // filters.filter_pairs_by_path
    if (all_pairs) {
      std::vector<double> dist(n, 0.0);  // geometry.accumulated_distances
      for (std::size_t i = 1; i < n; ++i) {
        dist[i] = dist[i - 1] + (poses[i - 1].translation() - poses[i].translation()).norm();
      }
      for (std::size_t i = 0; i + 1 < n; ++i) {
        std::size_t best = i + 1;
        double best_res = std::abs(dist[i + 1] - dist[i] - delta);
        for (std::size_t j = i + 2; j < n; ++j) {
          const double res = std::abs(dist[j] - dist[i] - delta);
          if (res < best_res) {
            best_res = res;
            best = j;
          }
        }
        if (best_res > tol) continue;
        pairs.emplace_back(i, best);
      }
    } else {
      std::vector<std::size_t> ids;
      double path = 0.0;
      for (std::size_t i = 0; i < n; ++i) {
        if (i > 0) path += (poses[i].translation() - poses[i - 1].translation()).norm();
        if (path >= delta) {
          ids.push_back(i);
          path = 0.0;
        }
      }
      for (std::size_t k = 0; k + 1 < ids.size(); ++k) pairs.emplace_back(ids[k], ids[k + 1]);
    }
  } else if (unit == DeltaUnit::kDegrees || unit == DeltaUnit::kRadians) {
    // filters.filter_pairs_by_angle; we compare in delta's unit throughout.
    const double to_unit = unit == DeltaUnit::kDegrees ? kRadToDeg : 1.0;
    const double bound = unit == DeltaUnit::kDegrees ? 180.0 : kPi;
    if (delta < 0.0 || delta > bound) return pairs;  // angle-axis angles are within [0, pi]
    if (all_pairs) {
      for (std::size_t i = 0; i + 1 < n; ++i) {
        for (std::size_t j = i + 1; j < n; ++j) {
          const double angle =
              RotationAngle(poses[i].linear().transpose() * poses[j].linear()) * to_unit;
          if (delta - tol <= angle && angle <= delta + tol) pairs.emplace_back(i, j);
        }
      }
    } else {
      double accumulated = 0.0;
      std::size_t start = 0;
      for (std::size_t i = 0; i + 1 < n; ++i) {
        accumulated +=
            RotationAngle(poses[i].linear().transpose() * poses[i + 1].linear()) * to_unit;
        if (accumulated >= delta) {
          pairs.emplace_back(start, i + 1);
          accumulated = 0.0;
          start = i + 1;
        }
      }
    }
  }
  return pairs;
}

Pose EvoRelativeError(const Pose& q_i, const Pose& q_j, const Pose& p_i, const Pose& p_j) {
  const Pose q_rel = q_i.inverse() * q_j;
  const Pose p_rel = p_i.inverse() * p_j;
  return q_rel.inverse() * p_rel;
}

Pose TumRelativeError(const Pose& q_i, const Pose& q_j, const Pose& p_i, const Pose& p_j,
                      double scale) {
  // evaluate_rpe.py: ominus(scale(ominus(P_j, P_i), s), ominus(Q_j, Q_i)), ominus(a, b) = a⁻¹ b.
  Eigen::Matrix4d p_rel = Inverse(p_j.matrix()) * p_i.matrix();
  p_rel.block<3, 1>(0, 3) *= scale;
  const Eigen::Matrix4d q_rel = Inverse(q_j.matrix()) * q_i.matrix();
  Pose e;
  e.matrix() = Inverse(p_rel) * q_rel;
  return e;
}

std::size_t TumFindClosestIndex(const std::vector<double>& list, double t) {
  std::size_t beginning = 0;
  double difference = std::abs(list[0] - t);
  std::size_t best = 0;
  std::size_t end = list.size();
  while (beginning < end) {
    const std::size_t middle = (end + beginning) / 2;
    if (std::abs(list[middle] - t) < difference) {
      difference = std::abs(list[middle] - t);
      best = middle;
    }
    if (t == list[middle]) return middle;
    if (list[middle] > t) {
      end = middle;
    } else {
      beginning = middle + 1;
    }
  }
  return best;
}

// ---------------------------------------------------------------------------------------------
// Whole evaluations

ApeResult EvaluateApe(const Trajectory& ref, const Trajectory& est, const ApeOptions& options,
                      const std::string& ref_name, const std::string& est_name) {
  ApeResult result;
  result.pairs = AssociateTrajectories(ref, est, options.association, ref_name, est_name);
  for (const IndexPair& p : result.pairs) {
    result.ref_poses.push_back(ref.poses[p.first]);
    result.est_poses.push_back(est.poses[p.second]);
    result.est_poses.back().translation() *= options.scale;
    result.stamps.push_back(est.stamps[p.second]);
  }
  result.alignment = AlignTrajectory(result.ref_poses, result.est_poses, options.alignment);
  if (result.alignment.degenerate) {
    result.message = result.alignment.reason;
    return result;
  }
  result.errors = ApeErrors(result.ref_poses, result.est_poses, options.relation);
  result.stats = ComputeStatistics(result.errors);
  result.ok = true;
  return result;
}

namespace {

RpeResult EvaluateRpeEvo(const Trajectory& ref, const Trajectory& est, const RpeOptions& options,
                         const std::string& ref_name, const std::string& est_name) {
  RpeResult result;
  const std::vector<IndexPair> assoc =
      AssociateTrajectories(ref, est, options.association, ref_name, est_name);
  std::vector<double> stamps;
  for (const IndexPair& p : assoc) {
    result.ref_poses.push_back(ref.poses[p.first]);
    result.est_poses.push_back(est.poses[p.second]);
    stamps.push_back(est.stamps[p.second]);
  }
  result.alignment = AlignTrajectory(result.ref_poses, result.est_poses, options.alignment);
  if (result.alignment.degenerate) {
    result.message = result.alignment.reason;
    return result;
  }
  if (options.delta_unit == DeltaUnit::kSeconds) {
    result.message = "delta unit 's' needs --tum (evo's units are f, m, deg, rad)";
    return result;
  }
  if (options.delta_unit == DeltaUnit::kFrames && options.delta != std::floor(options.delta)) {
    result.message = "delta must be an integer for unit frames";
    return result;
  }
  result.est_pairs = EvoRpePairs(result.est_poses, options.delta, options.delta_unit,
                                 options.rel_delta_tol, options.all_pairs);
  if (result.est_pairs.empty()) {
    result.message = "delta = " + FormatNumber(options.delta) + " (" +
                     ToString(options.delta_unit) + ") produced no pairs among " +
                     std::to_string(result.est_poses.size()) +
                     " poses; try a smaller delta or a looser tolerance";
    return result;
  }
  result.ref_pairs = result.est_pairs;
  std::vector<Pose> error_poses;
  for (const IndexPair& p : result.est_pairs) {
    const Pose e = EvoRelativeError(result.ref_poses[p.first], result.ref_poses[p.second],
                                    result.est_poses[p.first], result.est_poses[p.second]);
    error_poses.push_back(e);
    result.errors.push_back(ErrorOf(e, options.relation));
    result.stamps.push_back(stamps[p.second]);  // evo plots the error at the pair's end
  }
  result.stats = ComputeStatistics(result.errors);
  FillBothParts(error_poses, result);
  result.ok = true;
  return result;
}

/// Distances (or angles) along a trajectory, as evaluate_rpe.py: motion k = P_{k+1}⁻¹ P_k.
std::vector<double> TumAlongTrajectory(const std::vector<Pose>& poses, bool angles, double scale) {
  std::vector<double> along{0.0};
  double sum = 0.0;
  for (std::size_t k = 0; k + 1 < poses.size(); ++k) {
    const Eigen::Matrix4d motion = Inverse(poses[k + 1].matrix()) * poses[k].matrix();
    sum += angles ? RotationAngle(motion.topLeftCorner<3, 3>()) * scale
                  : motion.block<3, 1>(0, 3).norm();
    along.push_back(sum);
  }
  return along;
}

RpeResult EvaluateRpeTum(const Trajectory& ref, const Trajectory& est, const RpeOptions& options,
                         const std::string& est_name) {
  RpeResult result;
  if (ref.empty() || est.empty()) throw IoError(est_name, "no poses");
  result.ref_poses = ref.poses;
  result.est_poses = est.poses;
  // The tool's overlap check: distinct estimate stamps reached by a round trip est -> gt -> est.
  {
    std::vector<std::size_t> returned;
    for (double t : est.stamps) {
      const double t_gt =
          ref.stamps[TumFindClosestIndex(ref.stamps, t + options.association.offset)];
      returned.push_back(TumFindClosestIndex(est.stamps, t_gt - options.association.offset));
    }
    std::sort(returned.begin(), returned.end());
    returned.erase(std::unique(returned.begin(), returned.end()), returned.end());
    if (returned.size() < 2) {
      throw IoError(est_name,
                    "too little overlap in time with the ground truth (evaluate_rpe.py: "
                    "\"Number of overlap in the timestamps is too small\")");
    }
  }
  // Alignment has no effect on this RPE unless it scales; it is applied for plots and -s.
  if (options.alignment.align || options.alignment.correct_scale ||
      options.alignment.align_origin) {
    const std::vector<IndexPair> assoc =
        AssociateTum(ref.stamps, est.stamps, 0.02, options.association.offset);
    std::vector<Pose> r, e;
    for (const IndexPair& p : assoc) {
      r.push_back(ref.poses[p.first]);
      e.push_back(est.poses[p.second]);
    }
    AlignmentResult a = AlignTrajectory(r, e, options.alignment);
    if (a.degenerate) {
      result.alignment = a;
      result.message = a.reason;
      return result;
    }
    Pose t = Pose::Identity();
    t.linear() = a.umeyama.rotation;
    t.translation() = a.umeyama.translation;
    for (Pose& p : result.est_poses) {
      p.translation() *= a.umeyama.scale;
      p = a.origin * (t * p);
    }
    result.alignment = a;
  }
  const std::size_t n = est.size();
  std::vector<double> index_est;
  switch (options.delta_unit) {
    case DeltaUnit::kSeconds:
      index_est = est.stamps;
      break;
    case DeltaUnit::kMeters:
      index_est = TumAlongTrajectory(result.est_poses, false, 1.0);
      break;
    case DeltaUnit::kRadians:
      index_est = TumAlongTrajectory(result.est_poses, true, 1.0);
      break;
    case DeltaUnit::kDegrees:
      index_est = TumAlongTrajectory(result.est_poses, true, kRadToDeg);
      break;
    case DeltaUnit::kFrames:
      index_est.resize(n);
      std::iota(index_est.begin(), index_est.end(), 0.0);
      break;
  }
  std::vector<IndexPair> pairs;
  std::mt19937 rng(options.seed);
  if (!options.fixed_delta) {
    if (options.max_pairs == 0 ||
        static_cast<double>(n) < std::sqrt(static_cast<double>(options.max_pairs))) {
      for (std::size_t i = 0; i < n; ++i)
        for (std::size_t j = 0; j < n; ++j) pairs.emplace_back(i, j);
    } else {
      std::uniform_int_distribution<std::size_t> pick(0, n - 1);
      for (std::size_t k = 0; k < options.max_pairs; ++k) pairs.emplace_back(pick(rng), pick(rng));
    }
  } else {
    for (std::size_t i = 0; i < n; ++i) {
      const std::size_t j = TumFindClosestIndex(index_est, index_est[i] + options.delta);
      if (j != n - 1) pairs.emplace_back(i, j);
    }
    if (options.max_pairs != 0 && pairs.size() > options.max_pairs) {
      std::shuffle(pairs.begin(), pairs.end(), rng);
      pairs.resize(options.max_pairs);
      std::sort(pairs.begin(), pairs.end());
    }
  }
  std::vector<double> gt_steps;
  for (std::size_t k = 0; k + 1 < ref.size(); ++k) {
    gt_steps.push_back(ref.stamps[k + 1] - ref.stamps[k]);
  }
  const double gt_max_time_difference = 2.0 * Median(gt_steps);
  std::vector<Pose> error_poses;
  std::vector<double> rot_rad;
  for (const IndexPair& p : pairs) {
    const double t0 = est.stamps[p.first] + options.association.offset;
    const double t1 = est.stamps[p.second] + options.association.offset;
    const std::size_t g0 = TumFindClosestIndex(ref.stamps, t0);
    const std::size_t g1 = TumFindClosestIndex(ref.stamps, t1);
    if (std::abs(ref.stamps[g0] - t0) > gt_max_time_difference ||
        std::abs(ref.stamps[g1] - t1) > gt_max_time_difference) {
      continue;
    }
    const Pose e = TumRelativeError(ref.poses[g0], ref.poses[g1], result.est_poses[p.first],
                                    result.est_poses[p.second], options.scale);
    error_poses.push_back(e);
    result.est_pairs.push_back(p);
    result.ref_pairs.emplace_back(g0, g1);
    result.stamps.push_back(est.stamps[p.first]);  // the tool plots against the first stamp
    result.errors.push_back(ErrorOf(e, options.relation));
  }
  if (result.errors.size() < 2) {
    result.message =
        "fewer than 2 pose pairs matched the ground truth (evaluate_rpe.py: \"Couldn't find "
        "matching timestamp pairs\")";
    return result;
  }
  result.stats = ComputeStatistics(result.errors);
  FillBothParts(error_poses, result);
  result.ok = true;
  return result;
}

}  // namespace

RpeResult EvaluateRpe(const Trajectory& ref, const Trajectory& est, const RpeOptions& options,
                      const std::string& ref_name, const std::string& est_name) {
  return options.tum ? EvaluateRpeTum(ref, est, options, est_name)
                     : EvaluateRpeEvo(ref, est, options, ref_name, est_name);
}

}  // namespace planeslam::datasets
