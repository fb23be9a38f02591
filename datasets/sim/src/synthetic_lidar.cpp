// Rotating multi-beam LiDAR: ray casting in the world frame with per-firing origins, a uniform
// grid over the primitives and bounding-sphere culling in (row, column) space.
//
// The pinhole and spherical casters (synthetic_sensor.cpp) move a few dozen primitives into the
// sensor frame and cast rays from its origin; a street has thousands of primitives of which only
// those within range matter, and with motion distortion every firing has its own origin, so this
// caster keeps the primitives in the world frame and casts world rays instead.
#include "planeslam/datasets/synthetic_lidar.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "planeslam/datasets/errors.hpp"
#include "synthetic_random.hpp"

namespace planeslam::datasets {

namespace {

using Eigen::Vector3d;
constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180.0;
constexpr double kCell = 16.0;  // grid cell size [m]

enum class Kind { kPolygon, kDisk, kSphere, kCylinder };

/// One primitive in the world frame.
struct Prim {
  Kind kind = Kind::kPolygon;
  int label = 0;
  float albedo = 0.35f;
  Vector3d n = Vector3d::Zero();  // plane normal (polygon, disk) or cylinder axis
  double d = 0.0;                  // plane offset
  Vector3d c = Vector3d::Zero();  // disk/sphere centre, cylinder base
  double r = 0.0;
  double length = 0.0;
  std::vector<Vector3d> edge_n;  // polygon: inside iff edge_n[i].p >= edge_b[i]
  std::vector<double> edge_b;
  Vector3d bs_c = Vector3d::Zero();  // bounding sphere
  double bs_r = 0.0;
};

float Albedo(std::uint64_t key) {
  return static_cast<float>(0.15 + 0.45 * (MixSeed(key) >> 11) * 0x1.0p-53);
}

std::vector<Prim> Compile(const SyntheticScene& scene) {
  std::vector<Prim> prims;
  for (const ScenePlane& plane : scene.planes) {
    Prim p;
    p.label = plane.id;
    p.albedo = Albedo(static_cast<std::uint64_t>(plane.id));
    p.n = plane.normal;
    p.d = plane.d;
    if (plane.is_disk) {
      p.kind = Kind::kDisk;
      p.c = plane.disk_center;
      p.r = plane.disk_radius;
      p.bs_c = p.c;
      p.bs_r = p.r;
      prims.push_back(p);
      continue;
    }
    for (const auto& poly : plane.polygons) {
      Prim q = p;
      q.kind = Kind::kPolygon;
      Vector3d sum = Vector3d::Zero();
      for (std::size_t i = 0; i < poly.size(); ++i) {
        const Vector3d e = poly[(i + 1) % poly.size()] - poly[i];
        q.edge_n.push_back(q.n.cross(e));
        q.edge_b.push_back(q.edge_n.back().dot(poly[i]));
        sum += poly[i];
      }
      q.bs_c = sum / static_cast<double>(poly.size());
      for (const Vector3d& v : poly) q.bs_r = std::max(q.bs_r, (v - q.bs_c).norm());
      prims.push_back(q);
    }
  }
  for (const SceneSphere& s : scene.spheres) {
    Prim p;
    p.kind = Kind::kSphere;
    p.albedo = Albedo(0x5350ULL + prims.size());
    p.c = s.center;
    p.r = s.radius;
    p.bs_c = p.c;
    p.bs_r = p.r;
    prims.push_back(p);
  }
  for (const SceneCylinder& cyl : scene.cylinders) {
    Prim p;
    p.kind = Kind::kCylinder;
    p.albedo = Albedo(0x4359ULL + prims.size());
    p.n = cyl.axis;
    p.c = cyl.base;
    p.r = cyl.radius;
    p.length = cyl.length;
    p.bs_c = p.c + 0.5 * p.length * p.n;
    p.bs_r = std::sqrt(0.25 * p.length * p.length + p.r * p.r);
    prims.push_back(p);
  }
  return prims;
}

struct Hit {
  double s = std::numeric_limits<double>::infinity();
  int prim = -1;
};

/// Nearest hit of the ray o + s D (D unit, s > 0) with p; updates `hit` when nearer.
inline void Intersect(const Prim& p, int index, const Vector3d& o, const Vector3d& D, Hit& hit) {
  switch (p.kind) {
    case Kind::kPolygon: {
      const double denom = p.n.dot(D);
      if (denom == 0.0) return;
      const double s = (p.d - p.n.dot(o)) / denom;
      if (!(s > 0.0 && s < hit.s)) return;
      const Vector3d q = o + s * D;
      for (std::size_t i = 0; i < p.edge_n.size(); ++i) {
        if (p.edge_n[i].dot(q) < p.edge_b[i]) return;
      }
      hit.s = s;
      hit.prim = index;
      return;
    }
    case Kind::kDisk: {
      const double denom = p.n.dot(D);
      if (denom == 0.0) return;
      const double s = (p.d - p.n.dot(o)) / denom;
      if (!(s > 0.0 && s < hit.s)) return;
      if ((o + s * D - p.c).squaredNorm() > p.r * p.r) return;
      hit.s = s;
      hit.prim = index;
      return;
    }
    case Kind::kSphere: {
      const Vector3d w = o - p.c;
      const double b = w.dot(D), c = w.squaredNorm() - p.r * p.r;
      const double disc = b * b - c;
      if (disc < 0.0) return;
      const double sq = std::sqrt(disc);
      double s = -b - sq;
      if (s <= 0.0) s = -b + sq;
      if (s > 0.0 && s < hit.s) {
        hit.s = s;
        hit.prim = index;
      }
      return;
    }
    case Kind::kCylinder: {
      const Vector3d w = o - p.c;
      const double da = D.dot(p.n), wa = w.dot(p.n);
      const Vector3d dp = D - da * p.n, wp = w - wa * p.n;
      const double A = dp.squaredNorm();
      if (A == 0.0) return;
      const double B = wp.dot(dp), C = wp.squaredNorm() - p.r * p.r;
      const double disc = B * B - A * C;
      if (disc < 0.0) return;
      const double sq = std::sqrt(disc);
      for (double s : {(-B - sq) / A, (-B + sq) / A}) {
        if (s <= 0.0) continue;
        if (s >= hit.s) return;
        const double h = wa + s * da;
        if (h < 0.0 || h > p.length) continue;
        hit.s = s;
        hit.prim = index;
        return;
      }
      return;
    }
  }
}

Vector3d NormalAt(const Prim& p, const Vector3d& q) {
  switch (p.kind) {
    case Kind::kPolygon:
    case Kind::kDisk:
      return p.n;
    case Kind::kSphere:
      return (q - p.c).normalized();
    case Kind::kCylinder: {
      const Vector3d w = q - p.c;
      return (w - w.dot(p.n) * p.n).normalized();
    }
  }
  return p.n;
}

}  // namespace

std::vector<double> Hdl64ElevationsDeg() {
  // Upper block: 32 lasers from +2.0 to -8.33 deg; lower block: 32 from -8.87 to -24.8 deg.
  std::vector<double> el;
  for (int k = 0; k < 32; ++k) el.push_back(2.0 + (-8.33 - 2.0) * k / 31.0);
  for (int k = 0; k < 32; ++k) el.push_back(-8.87 + (-24.8 + 8.87) * k / 31.0);
  return el;
}

struct RotatingLidar::Impl {
  LidarSimConfig config;
  double period = 0.1;
  std::vector<double> elevations_deg;  // rows, highest first
  std::vector<double> elevations;      // [rad]
  std::vector<double> azimuths;        // per column [rad]
  std::vector<Vector3d> dirs;          // per pixel, sensor frame
  std::vector<Prim> prims;
  // Grid over the primitives' bounding spheres.
  double gx0 = 0.0, gy0 = 0.0;
  int gnx = 1, gny = 1;
  std::vector<std::vector<int>> cells;

  int W() const { return config.columns; }
  int H() const { return static_cast<int>(elevations.size()); }

  void BuildGrid() {
    double x0 = std::numeric_limits<double>::infinity(), y0 = x0, x1 = -x0, y1 = -x0;
    for (const Prim& p : prims) {
      x0 = std::min(x0, p.bs_c.x() - p.bs_r);
      y0 = std::min(y0, p.bs_c.y() - p.bs_r);
      x1 = std::max(x1, p.bs_c.x() + p.bs_r);
      y1 = std::max(y1, p.bs_c.y() + p.bs_r);
    }
    if (prims.empty()) x0 = y0 = x1 = y1 = 0.0;
    gx0 = x0;
    gy0 = y0;
    gnx = std::max(1, static_cast<int>(std::ceil((x1 - x0) / kCell)));
    gny = std::max(1, static_cast<int>(std::ceil((y1 - y0) / kCell)));
    cells.assign(static_cast<std::size_t>(gnx) * gny, {});
    for (std::size_t k = 0; k < prims.size(); ++k) {
      const Prim& p = prims[k];
      const int i0 = CellX(p.bs_c.x() - p.bs_r), i1 = CellX(p.bs_c.x() + p.bs_r);
      const int j0 = CellY(p.bs_c.y() - p.bs_r), j1 = CellY(p.bs_c.y() + p.bs_r);
      for (int j = j0; j <= j1; ++j)
        for (int i = i0; i <= i1; ++i) cells[static_cast<std::size_t>(j) * gnx + i].push_back(static_cast<int>(k));
    }
  }
  int CellX(double x) const {
    return std::clamp(static_cast<int>(std::floor((x - gx0) / kCell)), 0, gnx - 1);
  }
  int CellY(double y) const {
    return std::clamp(static_cast<int>(std::floor((y - gy0) / kCell)), 0, gny - 1);
  }

  /// Rows [r0, r1] and columns [c0, c1] (c may run past the width: wrap) whose rays can meet
  /// a sphere at q (reference sensor frame) of radius `radius`, with `widen` extra angle [rad].
  bool Box(const Vector3d& q, double radius, double widen, int* r0, int* r1, int* c0,
           int* c1) const {
    const double dist = q.norm();
    *r0 = 0;
    *r1 = H() - 1;
    *c0 = 0;
    *c1 = W() - 1;
    if (dist <= radius * (1.0 + 1e-9) + 1e-9) return true;
    const double alpha = std::asin(std::min(1.0, radius / dist)) + widen + 1e-9;
    const double el = std::asin(std::clamp(q.z() / dist, -1.0, 1.0));
    // Rows are sorted by decreasing elevation.
    while (*r0 < H() && elevations[*r0] > el + alpha) ++*r0;
    while (*r1 >= 0 && elevations[*r1] < el - alpha) --*r1;
    if (*r0 > *r1) return false;
    if (std::abs(el) + alpha >= 0.5 * kPi - 1e-9) return true;
    const double daz = std::asin(std::min(1.0, std::sin(alpha) / std::cos(el)));
    if (daz >= kPi - 1e-9) return true;
    const double az = std::atan2(q.y(), q.x());
    // Column c has azimuth pi - 2 pi (c + 0.25) / W.
    const double scale = W() / (2.0 * kPi);
    const int lo = static_cast<int>(std::floor((kPi - az - daz) * scale - 0.25)) - 1;
    const int hi = static_cast<int>(std::ceil((kPi - az + daz) * scale - 0.25)) + 1;
    if (hi - lo + 1 < W()) {
      *c0 = lo;
      *c1 = hi;
    }
    return true;
  }

  SyntheticRender Cast(const std::function<Pose(double)>& pose_at, bool moving,
                       std::uint64_t noise_seed) const;
};

RotatingLidar::RotatingLidar(const SyntheticScene& scene, const LidarSimConfig& config,
                             double scan_period)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.config = config;
  m.period = scan_period;
  PLANESLAM_CHECK(config.columns > 0 && scan_period > 0, "lidar: columns and period must be > 0");
  m.elevations_deg = config.elevations_deg.empty() ? Hdl64ElevationsDeg() : config.elevations_deg;
  std::sort(m.elevations_deg.begin(), m.elevations_deg.end(), std::greater<double>());
  for (double e : m.elevations_deg) m.elevations.push_back(e * kDeg);
  const int W = config.columns, H = m.H();
  for (int c = 0; c < W; ++c) m.azimuths.push_back(kPi - 2.0 * kPi * (c + 0.25) / W);
  m.dirs.resize(static_cast<std::size_t>(W) * H);
  for (int r = 0; r < H; ++r) {
    const double el = m.elevations[r];
    for (int c = 0; c < W; ++c) {
      const double az = m.azimuths[c];
      m.dirs[static_cast<std::size_t>(r) * W + c] =
          Vector3d(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el));
    }
  }
  m.prims = Compile(scene);
  m.BuildGrid();
}

RotatingLidar::~RotatingLidar() = default;

int RotatingLidar::Width() const { return impl_->W(); }
int RotatingLidar::Height() const { return impl_->H(); }
Eigen::Vector3d RotatingLidar::RayDirection(int row, int col) const {
  return impl_->dirs[static_cast<std::size_t>(row) * impl_->W() + col];
}
double RotatingLidar::ColumnTimeOffset(int col) const {
  return -impl_->azimuths[static_cast<std::size_t>(col)] / (2.0 * kPi) * impl_->period;
}
const std::vector<double>& RotatingLidar::ElevationsDeg() const { return impl_->elevations_deg; }
const LidarSimConfig& RotatingLidar::config() const { return impl_->config; }

SyntheticRender RotatingLidar::Render(const Pose& T_world_sensor, std::uint64_t noise_seed) const {
  return impl_->Cast([&T_world_sensor](double) { return T_world_sensor; }, false, noise_seed);
}

SyntheticRender RotatingLidar::RenderMoving(const std::function<Pose(double)>& pose_at,
                                            std::uint64_t noise_seed) const {
  return impl_->Cast(pose_at, impl_->config.motion_distortion, noise_seed);
}

SyntheticRender RotatingLidar::Impl::Cast(const std::function<Pose(double)>& pose_at, bool moving,
                                          std::uint64_t noise_seed) const {
  const int w = W(), h = H();
  const std::size_t n = static_cast<std::size_t>(w) * h;
  const Pose T0 = pose_at(0.0);
  const Eigen::Matrix3d R0t = T0.linear().transpose();
  const Vector3d o0 = T0.translation();
  // Per-column origin and world directions; how far the firings stray from the reference pose.
  thread_local std::vector<Vector3d> origins, world_dirs;
  origins.assign(static_cast<std::size_t>(w), o0);
  world_dirs.resize(n);
  double max_offset = 0.0, max_turn = 0.0;
  std::vector<Eigen::Matrix3d> rotations(static_cast<std::size_t>(w), T0.linear());
  if (moving) {
    for (int c = 0; c < w; ++c) {
      const Pose Tc = pose_at(-azimuths[c] / (2.0 * kPi) * period);
      origins[c] = Tc.translation();
      rotations[c] = Tc.linear();
      max_offset = std::max(max_offset, (origins[c] - o0).norm());
      max_turn = std::max(max_turn, Eigen::AngleAxisd(R0t * rotations[c]).angle());
    }
  }
  for (int r = 0; r < h; ++r) {
    for (int c = 0; c < w; ++c) {
      const std::size_t i = static_cast<std::size_t>(r) * w + c;
      world_dirs[i] = rotations[c] * dirs[i];
    }
  }
  // Primitives in the grid cells within reach.
  const double reach = config.max_range + max_offset;
  thread_local std::vector<int> candidates;
  thread_local std::vector<char> seen;
  candidates.clear();
  seen.assign(prims.size(), 0);
  for (int j = CellY(o0.y() - reach); j <= CellY(o0.y() + reach); ++j) {
    for (int i = CellX(o0.x() - reach); i <= CellX(o0.x() + reach); ++i) {
      for (int k : cells[static_cast<std::size_t>(j) * gnx + i]) {
        if (!seen[k]) {
          seen[k] = 1;
          candidates.push_back(k);
        }
      }
    }
  }
  std::sort(candidates.begin(), candidates.end());
  thread_local std::vector<Hit> hits;
  hits.assign(n, Hit{});
  for (int k : candidates) {
    const Prim& p = prims[k];
    const Vector3d q = R0t * (p.bs_c - o0);
    if (q.norm() - p.bs_r > reach) continue;
    int r0, r1, c0, c1;
    if (!Box(q, p.bs_r + max_offset, max_turn, &r0, &r1, &c0, &c1)) continue;
    for (int r = r0; r <= r1; ++r) {
      const std::size_t row = static_cast<std::size_t>(r) * w;
      for (int cc = c0; cc <= c1; ++cc) {
        const int c = ((cc % w) + w) % w;
        Intersect(p, k, origins[c], world_dirs[row + c], hits[row + c]);
      }
    }
  }
  // Measurements.
  SyntheticRender out;
  out.cloud = OrganizedCloud(w, h, SensorModel::kSpherical);
  out.labels = Image16(w, h);
  out.true_range.assign(n, std::numeric_limits<float>::quiet_NaN());
  out.intensity.assign(n, 0.0f);
  const double cos_max = std::cos(config.max_incidence_deg * kDeg);
  SplitMixRandom rng(noise_seed);
  for (std::size_t i = 0; i < n; ++i) {
    const Hit& hit = hits[i];
    if (hit.prim < 0) continue;
    out.true_range[i] = static_cast<float>(hit.s);
    if (hit.s < config.min_range || hit.s > config.max_range) continue;
    const Prim& p = prims[static_cast<std::size_t>(hit.prim)];
    const int c = static_cast<int>(i % static_cast<std::size_t>(w));
    const Vector3d& D = world_dirs[i];
    const double cos_inc = std::abs(NormalAt(p, origins[c] + hit.s * D).dot(D));
    if (cos_inc < cos_max) continue;
    if (config.dropout_rate > 0.0 && rng.Uniform() < config.dropout_rate) continue;
    double range = hit.s;
    if (config.noise) range += config.range_sigma * rng.TruncatedNormal(config.noise_truncation);
    // The firing's own frame: the point lies along the pixel's sensor-frame direction.
    out.cloud.points[i] = (range * dirs[i]).cast<float>();
    out.labels.data[i] = static_cast<std::uint16_t>(p.label);
    out.intensity[i] = p.albedo * static_cast<float>(0.3 + 0.7 * cos_inc);
  }
  return out;
}

}  // namespace planeslam::datasets
