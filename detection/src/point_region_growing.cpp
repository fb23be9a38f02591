#include "planeslam/detection/point_region_growing.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <vector>

#include "planeslam/datasets/errors.hpp"
#include "region_common.hpp"

namespace planeslam::detection {
namespace {

using Clock = std::chrono::steady_clock;
double Ms(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

struct Workspace {
  std::vector<std::int32_t> labels;   ///< region index (accepted or growing), -1 none
  std::vector<std::uint8_t> visited;  ///< in some region, accepted or not: never a seed again
  std::vector<float> rel2;            ///< (sigma(z)/z)^2 per pixel
  std::vector<int> members;
  std::vector<MomentSums> regions;
  std::vector<FastFit> fits;                ///< of accepted regions, at acceptance
  std::vector<std::pair<int, int>> stolen;  ///< (point, previous region) of this growth
};

Workspace& ThreadWorkspace() {
  thread_local Workspace ws;
  return ws;
}

}  // namespace

std::vector<std::string> PointParams::Validate() const {
  std::vector<std::string> problems;
  if (seed_neighbours < 2 || seed_neighbours > 8)
    problems.push_back("seed_neighbours must be in [2, 8]");
  if (!(alpha > 0 && alpha < 1)) problems.push_back("alpha must be in (0, 1)");
  if (!(beta > 0 && beta < 1)) problems.push_back("beta must be in (0, 1)");
  if (refit_interval < 0) problems.push_back("refit_interval must be >= 0 (0 = adaptive)");
  return problems;
}

PointRegionGrowing::PointRegionGrowing(const DetectionParams& params, const PointParams& point,
                                       std::string name)
    : params_(params), point_(point), name_(std::move(name)) {
  auto problems = params_.Validate();
  auto more = point_.Validate();
  problems.insert(problems.end(), more.begin(), more.end());
  PLANESLAM_CHECK(problems.empty(), "invalid PBRG parameters: " << problems.front());
}

Segmentation PointRegionGrowing::Detect(const datasets::OrganizedCloud& cloud) const {
  Segmentation out;
  const int width = cloud.width, height = cloud.height;
  PLANESLAM_CHECK(cloud.points.size() == static_cast<std::size_t>(width) * height,
                  "organized cloud size mismatch");
  out.width = width;
  out.height = height;
  const std::size_t n = cloud.points.size();
  if (n == 0) return out;
  const bool spherical = cloud.model == datasets::SensorModel::kSpherical;
  const bool depth_model = params_.model == ThresholdModel::kDepth;
  const Eigen::Vector3f* pts = cloud.points.data();
  Workspace& ws = ThreadWorkspace();

  const auto t0 = Clock::now();
  ws.labels.assign(n, -1);
  ws.visited.assign(n, 0);
  ws.rel2.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector3f& p = pts[i];
    if (!std::isfinite(p.z())) {
      ws.rel2[i] = -1.0f;  // invalid
      continue;
    }
    const double z = internal::PointDepth(p, spherical);
    const double rel = params_.Sigma(z) / z;
    ws.rel2[i] = static_cast<float>(rel * rel);
  }
  ws.regions.clear();
  ws.fits.clear();
  const int refit_interval = point_.refit_interval;

  const auto t1 = Clock::now();
  for (std::size_t s = 0; s < n; ++s) {
    if (ws.rel2[s] < 0 || ws.visited[s]) continue;
    const int sx = static_cast<int>(s % width), sy = static_cast<int>(s / width);
    const Eigen::Vector3f& ps = pts[s];
    const double zs = internal::PointDepth(ps, spherical);
    const float delta_s = static_cast<float>(params_.Delta(zs));
    // (a) neighbours of the 3x3 window within delta (not in an accepted plane).
    int nb[8];
    int n_nb = 0;
    for (int oy = -1; oy <= 1; ++oy) {
      const int y = sy + oy;
      if (y < 0 || y >= height) continue;
      for (int ox = -1; ox <= 1; ++ox) {
        const int x = sx + ox;
        if ((ox == 0 && oy == 0) || x < 0 || x >= width) continue;
        const int i = y * width + x;
        if (ws.rel2[i] < 0 || ws.labels[i] >= 0 || ws.visited[i]) continue;
        if ((pts[i] - ps).norm() < delta_s) nb[n_nb++] = i;
      }
    }
    if (n_nb < point_.seed_neighbours) continue;
    // (b) local planarity by the grid shape test.
    MomentSums region;
    region.Add(ps.x(), ps.y(), ps.z(), ws.rel2[s]);
    for (int j = 0; j < n_nb; ++j) {
      const Eigen::Vector3f& q = pts[nb[j]];
      region.Add(q.x(), q.y(), q.z(), ws.rel2[nb[j]]);
    }
    FastFit fit = FitSums(region);
    if (fit.l2 <= point_.alpha * fit.l3) continue;  // linear
    bool planar = fit.l1 <= point_.beta * fit.l2;
    if (!planar && depth_model) {
      const double noise = region.EffectiveMse(fit.normal, region.NormalTilt(fit.l2));
      planar = fit.mse <= params_.planar_sigmas * params_.planar_sigmas * noise;
    }
    if (!planar) continue;

    // Grow (Algorithm 1 lines 6-12).
    const int r = static_cast<int>(ws.regions.size());
    ws.members.clear();
    ws.members.push_back(static_cast<int>(s));
    for (int j = 0; j < n_nb; ++j) ws.members.push_back(nb[j]);
    for (int m : ws.members) {
      ws.labels[m] = r;
      ws.visited[m] = 1;
    }
    std::size_t head = 0;
    double since_refit = 0;
    while (head < ws.members.size()) {
      const int q = ws.members[head++];
      const int qx = q % width, qy = q / width;
      const Eigen::Vector3f& pq = pts[q];
      for (int dir = 0; dir < 4; ++dir) {
        int c;
        if (dir == 0) {
          if (qx + 1 >= width) continue;
          c = q + 1;
        } else if (dir == 1) {
          if (qx == 0) continue;
          c = q - 1;
        } else if (dir == 2) {
          if (qy + 1 >= height) continue;
          c = q + width;
        } else {
          if (qy == 0) continue;
          c = q - width;
        }
        const int owner = ws.labels[c];
        if (owner == r || ws.rel2[c] < 0) continue;
        if (owner < 0 && ws.visited[c]) continue;  // in R': left PCD (Algorithm 1 line 3)
        const Eigen::Vector3f& pcf = pts[c];
        const double zc = internal::PointDepth(pcf, spherical);
        const double delta_c = params_.Delta(zc);
        if ((pcf - pq).squaredNorm() >= delta_c * delta_c) continue;  // dis(GR, p_c) < delta
        const Eigen::Vector3d pc = pcf.cast<double>();
        MomentSums merged = region;
        merged.Add(pc.x(), pc.y(), pc.z(), ws.rel2[c]);
        // Tolerances: point noise along the normal (sigma |n.p| / z), and for a young region the
        // normal's own uncertainty times the lever arm from the centroid (as in GBRG).
        auto gamma_for = [&](const FastFit& f, const MomentSums& m) {
          if (!depth_model) return params_.gamma;
          const double tilt = std::min(1.0, m.NormalTilt(f.l2));
          const double sn = std::sqrt(ws.rel2[c]) * std::abs(f.normal.dot(pc));
          if (tilt <= 0.02) return params_.Gamma(sn);  // a sharp normal: no lever-arm term
          const Eigen::Vector3d diff = pc - f.centroid;
          const double off = f.normal.dot(diff);
          const double lateral = std::sqrt(std::max(0.0, diff.squaredNorm() - off * off));
          return params_.Gamma(sn) + tilt * lateral;
        };
        bool accept;
        FastFit new_fit;
        bool refitted = false;
        const bool exact = refit_interval == 1;
        if (!exact) {
          // Approximate distance test against the current plane; MSE bound about its normal.
          // Each bound is at least its cheap part (the base gamma; epsilon of the noise along
          // the normal alone, which the tilt term only raises): within that, no roots needed.
          const double dist = std::abs(fit.normal.dot(pc) - fit.d);
          if (dist >= params_.gamma && dist >= gamma_for(fit, region)) continue;
          if (MseAboutWithinEpsilon(merged, fit.normal, params_) ||
              merged.MseAbout(fit.normal) <
                  params_.Epsilon(merged.EffectiveMse(fit.normal, merged.NormalTilt(fit.l2)),
                                  merged.k)) {
            accept = true;
          } else {
            new_fit = RefitFrom(merged, fit.normal);
            refitted = true;
            accept =
                new_fit.mse <
                params_.Epsilon(merged.EffectiveMse(new_fit.normal, merged.NormalTilt(new_fit.l2)),
                                merged.k);
          }
        } else {
          new_fit = RefitFrom(merged, fit.normal);
          refitted = true;
          const double dist = std::abs(new_fit.normal.dot(pc) - new_fit.d);
          accept = dist < gamma_for(new_fit, merged) &&
                   new_fit.mse < params_.Epsilon(merged.EffectiveMse(new_fit.normal,
                                                                     merged.NormalTilt(new_fit.l2)),
                                                 merged.k);
        }
        if (!accept) continue;
        if (owner >= 0) {
          // A joint point already in an earlier plane (the paper's shared points): it stays
          // with the plane it fits best, in units of each plane's tolerance at that point.
          const FastFit& cur = refitted ? new_fit : fit;
          const FastFit& old = ws.fits[owner];
          const double t_new = gamma_for(cur, merged), t_old = gamma_for(old, ws.regions[owner]);
          if (std::abs(old.normal.dot(pc) - old.d) / t_old <=
              std::abs(cur.normal.dot(pc) - cur.d) / t_new)
            continue;
          MomentSums one;
          one.Add(pc.x(), pc.y(), pc.z(), ws.rel2[c]);
          ws.regions[owner].Subtract(one);
          ws.stolen.emplace_back(c, owner);
        }
        region = merged;
        since_refit += 1.0;
        if (refitted) {
          fit = new_fit;
          since_refit = 0;
        } else {
          const double interval =
              refit_interval > 0 ? refit_interval : std::max(1.0, region.k / 64.0);
          if (since_refit >= interval) {
            fit = RefitFrom(region, fit.normal);
            since_refit = 0;
          }
        }
        ws.labels[c] = r;
        ws.visited[c] = 1;
        ws.members.push_back(c);
      }
    }
    if (static_cast<int>(ws.members.size()) >= params_.theta) {
      ws.regions.push_back(region);
      ws.fits.push_back(FitSums(region));
    } else {
      for (int m : ws.members) ws.labels[m] = -1;     // R': out of PCD, no seed, no growth
      for (const auto& [point, owner] : ws.stolen) {  // joint points go back to their plane
        const Eigen::Vector3f& q = pts[point];
        ws.regions[owner].Add(q.x(), q.y(), q.z(), ws.rel2[point]);
        ws.labels[point] = owner;
      }
    }
    ws.stolen.clear();
  }

  const auto t2 = Clock::now();
  internal::FinalizeLabelImage(cloud, ws.labels, ws.regions, params_, out);
  const auto t3 = Clock::now();
  out.timings_ms = {{"prepare", Ms(t0, t1)}, {"grow", Ms(t1, t2)}, {"finalize", Ms(t2, t3)}};
  return out;
}

}  // namespace planeslam::detection
