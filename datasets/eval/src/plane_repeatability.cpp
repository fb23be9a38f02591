#include "planeslam/datasets/plane_repeatability.hpp"

#include <algorithm>
#include <cmath>
#include <tuple>

#include "planeslam/datasets/errors.hpp"

namespace planeslam::datasets {
namespace {

double Median(std::vector<double> v) {
  if (v.empty()) return -1.0;
  const std::size_t mid = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid), v.end());
  const double upper = v[mid];
  if (v.size() % 2 == 1) return upper;
  const double lower = *std::max_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid));
  return 0.5 * (lower + upper);
}

}  // namespace

RepeatabilityPlane TransformPlane(const RepeatabilityPlane& plane_j, const Pose& T_i_j) {
  RepeatabilityPlane out = plane_j;
  out.normal = T_i_j.linear() * plane_j.normal;
  // A point p_j on the plane maps to p_i = R p_j + t: n_i.p_i = n_j.p_j + n_i.t = d_j + n_i.t.
  out.d = plane_j.d + out.normal.dot(T_i_j.translation());
  if (out.d < 0.0) {
    out.normal = -out.normal;
    out.d = -out.d;
  }
  return out;
}

RepeatabilityResult MatchPlanes(const std::vector<RepeatabilityPlane>& planes_i,
                                const std::vector<RepeatabilityPlane>& planes_j,
                                const Pose& T_i_j, const RepeatabilityOptions& options) {
  PLANESLAM_CHECK(options.max_angle_deg > 0.0 && options.max_offset > 0.0,
                  "gates must be positive: " << options.max_angle_deg << " deg, "
                                             << options.max_offset << " m");
  std::vector<RepeatabilityPlane> mapped;
  mapped.reserve(planes_j.size());
  for (const auto& p : planes_j) mapped.push_back(TransformPlane(p, T_i_j));

  // Candidate pairs (cost, i, j, angle, offset).
  std::vector<std::tuple<double, int, int, double, double>> candidates;
  for (std::size_t a = 0; a < planes_i.size(); ++a) {
    const Eigen::Vector3d ni = planes_i[a].normal.normalized();
    for (std::size_t b = 0; b < mapped.size(); ++b) {
      Eigen::Vector3d nj = mapped[b].normal.normalized();
      double dj = mapped[b].d;
      // Orient alike before comparing offsets (planes through the origin have an ambiguous sign).
      if (ni.dot(nj) < 0.0) {
        nj = -nj;
        dj = -dj;
      }
      const double angle = std::atan2(ni.cross(nj).norm(), ni.dot(nj)) * 180.0 / M_PI;
      const double offset = std::abs(planes_i[a].d - dj);
      if (angle > options.max_angle_deg || offset > options.max_offset) continue;
      const double cost = angle / options.max_angle_deg + offset / options.max_offset;
      candidates.emplace_back(cost, static_cast<int>(a), static_cast<int>(b), angle, offset);
    }
  }
  std::sort(candidates.begin(), candidates.end());

  RepeatabilityResult result;
  std::vector<bool> used_i(planes_i.size(), false), used_j(planes_j.size(), false);
  for (const auto& [cost, a, b, angle, offset] : candidates) {
    if (used_i[a] || used_j[b]) continue;
    used_i[a] = used_j[b] = true;
    PlanePairMatch m;
    m.index_i = a;
    m.index_j = b;
    m.angle_deg = angle;
    m.offset_m = offset;
    m.large = planes_i[a].point_count >= options.large_pixels;
    result.matches.push_back(m);
  }
  std::sort(result.matches.begin(), result.matches.end(),
            [](const PlanePairMatch& x, const PlanePairMatch& y) { return x.index_i < y.index_i; });
  for (std::size_t a = 0; a < planes_i.size(); ++a) {
    if (planes_i[a].point_count < options.large_pixels) continue;
    ++result.large_planes;
    if (used_i[a]) ++result.large_matched;
  }
  return result;
}

void RepeatabilitySummary::Add(const RepeatabilityResult& result) {
  ++frame_pairs;
  large_planes += result.large_planes;
  large_matched += result.large_matched;
  for (const auto& m : result.matches) {
    if (!m.large) continue;
    angles_deg.push_back(m.angle_deg);
    offsets_m.push_back(m.offset_m);
  }
}

double RepeatabilitySummary::MedianAngleDeg() const { return Median(angles_deg); }
double RepeatabilitySummary::MedianOffset() const { return Median(offsets_m); }

}  // namespace planeslam::datasets
