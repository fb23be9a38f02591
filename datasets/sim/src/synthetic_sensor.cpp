// Exact ray casting of SyntheticScene primitives for the pinhole and spherical sensors.
//
// Speed: the scene is moved into the sensor frame once per frame (a few dozen primitives), so
// every ray starts at the origin. Each primitive is then tested only against the pixels of a
// conservative image-space box: for the pinhole camera the projection of its (near-clipped)
// bounding hull, for the spherical scanner the elevation/azimuth extent of its bounding sphere.
// Rays are scaled so the ray parameter s is the pinhole depth z (D = (x', y', 1)) or the range
// (unit D), which the nearest-hit test compares directly.
#include <algorithm>
#include <cmath>
#include <limits>

#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/synthetic_sensor.hpp"
#include "synthetic_random.hpp"

namespace planeslam::datasets {

namespace {

using Eigen::Vector3d;
constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180.0;

enum class Kind { kPolygon, kDisk, kSphere, kCylinder };

/// One primitive (a convex polygon piece, a disk, a sphere or a cylinder's lateral surface).
struct Primitive {
  Kind kind = Kind::kPolygon;
  int label = 0;
  Vector3d n = Vector3d::Zero();  // plane normal (polygon, disk) or cylinder axis
  double d = 0.0;                  // plane offset
  Vector3d c = Vector3d::Zero();  // disk/sphere centre, cylinder base
  double r = 0.0;                  // radius
  double length = 0.0;             // cylinder length
  std::vector<Vector3d> verts;     // polygon corners
  std::vector<Vector3d> edge_n;    // inward edge normals m_i (polygon): inside iff m_i.p >= e_b_i
  std::vector<double> edge_b;
  std::vector<Vector3d> hull;      // points whose convex hull contains the primitive
  Vector3d bs_center = Vector3d::Zero();  // bounding sphere
  double bs_radius = 0.0;
};

std::vector<Primitive> Compile(const SyntheticScene& scene) {
  std::vector<Primitive> prims;
  for (const ScenePlane& plane : scene.planes) {
    if (plane.is_disk) {
      Primitive p;
      p.kind = Kind::kDisk;
      p.label = plane.id;
      p.n = plane.normal;
      p.d = plane.d;
      p.c = plane.disk_center;
      p.r = plane.disk_radius;
      prims.push_back(p);
      continue;
    }
    for (const auto& poly : plane.polygons) {
      Primitive p;
      p.kind = Kind::kPolygon;
      p.label = plane.id;
      p.n = plane.normal;
      p.d = plane.d;
      p.verts = poly;
      prims.push_back(p);
    }
  }
  for (const SceneSphere& s : scene.spheres) {
    Primitive p;
    p.kind = Kind::kSphere;
    p.c = s.center;
    p.r = s.radius;
    prims.push_back(p);
  }
  for (const SceneCylinder& cyl : scene.cylinders) {
    Primitive p;
    p.kind = Kind::kCylinder;
    p.n = cyl.axis;
    p.c = cyl.base;
    p.r = cyl.radius;
    p.length = cyl.length;
    prims.push_back(p);
  }
  return prims;
}

Vector3d AnyPerpendicular(const Vector3d& n) {
  const Vector3d t = std::abs(n.x()) < 0.9 ? Vector3d::UnitX() : Vector3d::UnitY();
  return n.cross(t).normalized();
}

/// The primitive moved by T (sensor <- world), with its derived culling data.
Primitive Transform(const Primitive& w, const Pose& T) {
  Primitive p = w;
  const Eigen::Matrix3d R = T.linear();
  p.n = R * w.n;
  p.c = T * w.c;
  for (auto& v : p.verts) v = T * v;
  p.hull.clear();
  switch (p.kind) {
    case Kind::kPolygon: {
      p.d = p.n.dot(p.verts[0]);
      p.edge_n.resize(p.verts.size());
      p.edge_b.resize(p.verts.size());
      Vector3d s = Vector3d::Zero();
      for (std::size_t i = 0; i < p.verts.size(); ++i) {
        const Vector3d e = p.verts[(i + 1) % p.verts.size()] - p.verts[i];
        p.edge_n[i] = p.n.cross(e);
        p.edge_b[i] = p.edge_n[i].dot(p.verts[i]);
        s += p.verts[i];
      }
      p.bs_center = s / static_cast<double>(p.verts.size());
      for (const auto& v : p.verts) p.bs_radius = std::max(p.bs_radius, (v - p.bs_center).norm());
      p.hull = p.verts;
      break;
    }
    case Kind::kDisk: {
      p.d = p.n.dot(p.c);
      p.bs_center = p.c;
      p.bs_radius = p.r;
      const Vector3d a = AnyPerpendicular(p.n), b = p.n.cross(a);
      for (double sa : {-1.0, 1.0})
        for (double sb : {-1.0, 1.0}) p.hull.push_back(p.c + p.r * (sa * a + sb * b));
      break;
    }
    case Kind::kSphere:
      p.bs_center = p.c;
      p.bs_radius = p.r;
      for (int k = 0; k < 8; ++k) {
        p.hull.push_back(p.c + p.r * Vector3d((k & 1) ? 1 : -1, (k & 2) ? 1 : -1,
                                              (k & 4) ? 1 : -1));
      }
      break;
    case Kind::kCylinder: {
      const Vector3d top = p.c + p.length * p.n;
      p.bs_center = 0.5 * (p.c + top);
      p.bs_radius = std::sqrt(0.25 * p.length * p.length + p.r * p.r);
      // Box around both end disks: extent r * sqrt(1 - a_i^2) per axis (exact AABB of a disk).
      const Vector3d ext(p.r * std::sqrt(std::max(0.0, 1.0 - p.n.x() * p.n.x())),
                         p.r * std::sqrt(std::max(0.0, 1.0 - p.n.y() * p.n.y())),
                         p.r * std::sqrt(std::max(0.0, 1.0 - p.n.z() * p.n.z())));
      const Vector3d lo = p.c.cwiseMin(top) - ext, hi = p.c.cwiseMax(top) + ext;
      for (int k = 0; k < 8; ++k) {
        p.hull.emplace_back((k & 1) ? hi.x() : lo.x(), (k & 2) ? hi.y() : lo.y(),
                            (k & 4) ? hi.z() : lo.z());
      }
      break;
    }
  }
  return p;
}

/// Nearest-hit state of one pixel.
struct Hit {
  double s = std::numeric_limits<double>::infinity();
  int prim = -1;
};

/// Whether a hit at s on primitive `index` beats `hit`: nearer, or as near and listed earlier. The
/// tie rule makes the result the same whatever order the primitives are cast in.
inline bool Nearer(double s, int index, const Hit& hit) {
  return s < hit.s || (s == hit.s && index < hit.prim);
}

/// Tests ray D (ray parameter s, hit point s * D) against p; updates `hit` when nearer.
inline void Intersect(const Primitive& p, int index, const Vector3d& D, double D2, Hit& hit) {
  switch (p.kind) {
    case Kind::kPolygon: {
      const double denom = p.n.dot(D);
      if (denom == 0.0) return;
      const double s = p.d / denom;
      if (!(s > 0.0 && Nearer(s, index, hit))) return;
      const Vector3d q = s * D;
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
      const double s = p.d / denom;
      if (!(s > 0.0 && Nearer(s, index, hit))) return;
      if ((s * D - p.c).squaredNorm() > p.r * p.r) return;
      hit.s = s;
      hit.prim = index;
      return;
    }
    case Kind::kSphere: {
      const double b = p.c.dot(D);
      const double c = p.c.squaredNorm() - p.r * p.r;
      const double disc = b * b - D2 * c;
      if (disc < 0.0) return;
      const double sq = std::sqrt(disc);
      double s = (b - sq) / D2;
      if (s <= 0.0) s = (b + sq) / D2;
      if (s > 0.0 && Nearer(s, index, hit)) {
        hit.s = s;
        hit.prim = index;
      }
      return;
    }
    case Kind::kCylinder: {
      const Vector3d w = -p.c;
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
        if (!Nearer(s, index, hit)) return;
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

/// Unit surface normal of primitive p at point q (sensor frame).
Vector3d NormalAt(const Primitive& p, const Vector3d& q) {
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

/// Shared part of both sensors: primitives, per-pixel rays and the nearest-hit search.
class CasterBase : public SyntheticSensor {
 public:
  CasterBase(const SyntheticScene& scene, int width, int height)
      : prims_(Compile(scene)), width_(width), height_(height) {
    rays_.resize(static_cast<std::size_t>(width) * height);
    ray_norm2_.resize(rays_.size());
    ray_norm_.resize(rays_.size());
  }
  int Width() const override { return width_; }
  int Height() const override { return height_; }
  Vector3d RayDirection(int row, int col) const override {
    return rays_[static_cast<std::size_t>(row) * width_ + col].normalized();
  }

 protected:
  struct PixelBox {
    int r0 = 0, r1 = -1, c0 = 0, c1 = -1;  // inclusive; columns may exceed the width (wrap)
  };
  virtual PixelBox Cull(const Primitive& p) const = 0;
  virtual bool WrapColumns() const { return false; }
  /// A specialised loop over `box` for primitive p; false when there is none (generic path).
  virtual bool FastLoop(const Primitive&, int, const PixelBox&, std::vector<Hit>&) const {
    return false;
  }

  /// Nearest hit per pixel and the primitives in the sensor frame.
  void Cast(const Pose& T_world_sensor, std::vector<Hit>& hits,
            std::vector<Primitive>& local, double max_s) const {
    const Pose T_sensor_world = T_world_sensor.inverse();
    local.clear();
    local.reserve(prims_.size());
    for (const Primitive& p : prims_) local.push_back(Transform(p, T_sensor_world));
    hits.assign(rays_.size(), Hit{});
    // Nearest first, so that pixels already hit in front skip the inside tests of what is behind
    // (the nearest hit does not depend on the order, see Nearer()).
    thread_local std::vector<std::pair<double, std::size_t>> order;
    order.clear();
    for (std::size_t k = 0; k < local.size(); ++k) {
      order.emplace_back(local[k].bs_center.norm() - local[k].bs_radius, k);
    }
    std::sort(order.begin(), order.end());
    for (const auto& [nearest, k] : order) {
      const Primitive& p = local[k];
      // Everything this primitive could show is beyond range: skip. The range of a hit is
      // s * |D| <= s * max_ray_norm_, so s > max_s whenever range > max_s * max_ray_norm_.
      if (nearest > max_s * max_ray_norm_) continue;
      const PixelBox box = Cull(p);
      if (FastLoop(p, static_cast<int>(k), box, hits)) continue;
      for (int r = box.r0; r <= box.r1; ++r) {
        for (int cc = box.c0; cc <= box.c1; ++cc) {
          int c = cc;
          if (WrapColumns()) c = ((cc % width_) + width_) % width_;
          const std::size_t i = static_cast<std::size_t>(r) * width_ + c;
          Intersect(p, static_cast<int>(k), rays_[i], ray_norm2_[i], hits[i]);
        }
      }
    }
  }

  std::vector<Primitive> prims_;
  int width_;
  int height_;
  std::vector<Vector3d> rays_;  // per pixel, sensor frame
  std::vector<double> ray_norm2_;
  std::vector<double> ray_norm_;
  double max_ray_norm_ = 1.0;   // largest |D| over the pixels
};

/// Pinhole depth camera.
class PinholeCaster final : public CasterBase {
 public:
  PinholeCaster(const SyntheticScene& scene, const PinholeSimConfig& config)
      : CasterBase(scene, config.intrinsics.width, config.intrinsics.height), config_(config) {
    const PinholeIntrinsics& K = config.intrinsics;
    PLANESLAM_CHECK(K.width > 0 && K.height > 0 && K.fx > 0 && K.fy > 0, "bad intrinsics");
    for (int r = 0; r < height_; ++r) {
      for (int c = 0; c < width_; ++c) {
        const std::size_t i = static_cast<std::size_t>(r) * width_ + c;
        rays_[i] = Vector3d((c - K.cx) / K.fx, (r - K.cy) / K.fy, 1.0);
        ray_norm2_[i] = rays_[i].squaredNorm();
        ray_norm_[i] = std::sqrt(ray_norm2_[i]);
      }
    }
    for (double n2 : ray_norm2_) max_ray_norm_ = std::max(max_ray_norm_, std::sqrt(n2));
    for (int c = 0; c < width_; ++c) xs_.push_back((c - K.cx) / K.fx);
    for (int r = 0; r < height_; ++r) ys_.push_back((r - K.cy) / K.fy);
  }
  SensorModel Model() const override { return SensorModel::kPinhole; }

  /// Polygons: with D = (x, y, 1) the plane denominator n.D and the edge terms m_i.D are affine
  /// in x and y, so the row parts are computed once per row (same tests as Intersect()).
  /// Each row is tested only over the columns its span can cover: multiplied by den (whose sign
  /// is that of d wherever s = d / den > 0), edge test i, s (m_i.D) >= b_i, becomes the linear
  /// |d| (m_i.D) - sign(d) b_i den >= 0 in x, and the span is the intersection of these
  /// half-lines, widened by a relative tolerance far above rounding and by a column on each side.
  /// The exact test still decides every pixel of the span, so the hits are the same.
  bool FastLoop(const Primitive& p, int index, const PixelBox& box,
                std::vector<Hit>& hits) const override {
    if (p.kind != Kind::kPolygon || p.edge_n.size() > kMaxEdges) return false;
    if (box.r0 > box.r1 || box.c0 > box.c1) return true;  // culled: no pixel to test
    if (p.d == 0.0) return true;  // the plane passes through the eye: s = 0 is never a hit
    const std::size_t m = p.edge_n.size();
    const double sign = p.d > 0.0 ? 1.0 : -1.0, abs_d = std::abs(p.d);
    const double x_max = std::max(std::abs(xs_[static_cast<std::size_t>(box.c0)]),
                                  std::abs(xs_[static_cast<std::size_t>(box.c1)]));
    const double fx = config_.intrinsics.fx, cx = config_.intrinsics.cx;
    double row_term[kMaxEdges];
    for (int r = box.r0; r <= box.r1; ++r) {
      const double y = ys_[static_cast<std::size_t>(r)];
      const double den_r = p.n.y() * y + p.n.z();
      for (std::size_t e = 0; e < m; ++e) row_term[e] = p.edge_n[e].y() * y + p.edge_n[e].z();
      // Span [x_lo, x_hi] where every constraint a x + b >= -tol holds; s > 0 is one more.
      double x_lo = -std::numeric_limits<double>::infinity(), x_hi = -x_lo;
      bool empty = false;
      auto constrain = [&](double a, double b, double scale) {
        const double tol = 1e-9 * scale;
        if (a > 0.0) {
          x_lo = std::max(x_lo, (-b - tol) / a);
        } else if (a < 0.0) {
          x_hi = std::min(x_hi, (-b - tol) / a);
        } else if (b < -tol) {
          empty = true;
        }
      };
      constrain(sign * p.n.x(), sign * den_r, std::abs(p.n.x()) * x_max + std::abs(den_r));
      for (std::size_t e = 0; e < m; ++e) {
        const double ex = p.edge_n[e].x(), eb = p.edge_b[e];
        constrain(abs_d * ex - sign * eb * p.n.x(), abs_d * row_term[e] - sign * eb * den_r,
                  abs_d * (std::abs(ex) * x_max + std::abs(row_term[e])) +
                      std::abs(eb) * (std::abs(p.n.x()) * x_max + std::abs(den_r)));
      }
      if (empty || !(x_lo <= x_hi)) continue;
      // Columns c with x = (c - cx) / fx in the span, one more on each side.
      const double u_lo = x_lo * fx + cx - 1.0, u_hi = x_hi * fx + cx + 1.0;
      const int c0 = u_lo > box.c0 ? static_cast<int>(std::min<double>(std::floor(u_lo), box.c1 + 1))
                                   : box.c0;
      const int c1 = u_hi < box.c1 ? static_cast<int>(std::max<double>(std::ceil(u_hi), box.c0 - 1))
                                   : box.c1;
      Hit* row_hits = hits.data() + static_cast<std::size_t>(r) * width_;
      for (int c = c0; c <= c1; ++c) {
        const double x = xs_[static_cast<std::size_t>(c)];
        const double den = den_r + p.n.x() * x;
        if (den == 0.0) continue;
        const double s = p.d / den;
        Hit& h = row_hits[c];
        if (!(s > 0.0 && Nearer(s, index, h))) continue;
        bool inside = true;
        for (std::size_t e = 0; e < m && inside; ++e) {
          inside = s * (p.edge_n[e].x() * x + row_term[e]) >= p.edge_b[e];
        }
        if (!inside) continue;
        h.s = s;
        h.prim = index;
      }
    }
    return true;
  }

  SyntheticRender Render(const Pose& T_world_sensor, std::uint64_t noise_seed) const override {
    // Per-thread scratch, reused across frames (saves ~5 MB of fresh pages per frame).
    thread_local std::vector<Hit> hits;
    thread_local std::vector<Primitive> local;
    Cast(T_world_sensor, hits, local, config_.max_depth);
    SyntheticRender out;
    out.cloud = OrganizedCloud(width_, height_, SensorModel::kPinhole);
    out.labels = Image16(width_, height_);
    out.true_range.assign(hits.size(), std::numeric_limits<float>::quiet_NaN());
    // Validity from the exact geometry: range, incidence (|n.D| >= cos_max |D|), depth edges.
    const double cos_max = std::cos(config_.max_incidence_deg * kDeg);
    thread_local std::vector<char> valid;
    valid.assign(hits.size(), 0);
    for (std::size_t i = 0; i < hits.size(); ++i) {
      const Hit& h = hits[i];
      if (h.prim < 0) continue;
      out.true_range[i] = static_cast<float>(h.s);
      if (h.s < config_.min_depth || h.s > config_.max_depth) continue;
      const Vector3d& D = rays_[i];
      const Primitive& p = local[static_cast<std::size_t>(h.prim)];
      const double cos_d = p.kind == Kind::kPolygon || p.kind == Kind::kDisk
                               ? std::abs(p.n.dot(D))
                               : std::abs(NormalAt(p, h.s * D).dot(D));
      valid[i] = cos_d >= cos_max * ray_norm_[i];
    }
    if (config_.edge_dropout) {
      // A pixel is dropped when its depth differs from a 4-neighbour's (both hit) by more than
      // edge_jump times the smaller one; both sides of the jump go.
      thread_local std::vector<char> edge;
      edge.assign(hits.size(), 0);
      const double jump = config_.edge_jump;
      for (int r = 0; r < height_; ++r) {
        const std::size_t row = static_cast<std::size_t>(r) * width_;
        for (int c = 0; c < width_; ++c) {
          const std::size_t i = row + c;
          if (hits[i].prim < 0) continue;
          const double za = hits[i].s;
          if (c + 1 < width_ && hits[i + 1].prim >= 0) {
            const double zb = hits[i + 1].s;
            if (std::abs(za - zb) > jump * std::min(za, zb)) edge[i] = edge[i + 1] = 1;
          }
          if (r + 1 < height_ && hits[i + width_].prim >= 0) {
            const double zb = hits[i + width_].s;
            if (std::abs(za - zb) > jump * std::min(za, zb)) edge[i] = edge[i + width_] = 1;
          }
        }
      }
      for (std::size_t i = 0; i < hits.size(); ++i) valid[i] &= static_cast<char>(!edge[i]);
    }
    // Measurements: noise along the ray on depth, optional disparity quantisation.
    SplitMixRandom rng(noise_seed);
    const double fb = config_.intrinsics.fx * config_.baseline;
    for (std::size_t i = 0; i < hits.size(); ++i) {
      if (!valid[i]) continue;
      if (config_.dropout_rate > 0.0 && rng.Uniform() < config_.dropout_rate) continue;
      double z = hits[i].s;
      if (config_.noise) z += config_.noise_k * z * z * rng.TruncatedNormal(config_.noise_truncation);
      if (config_.quantize_disparity) {
        // Kinect v1: disparity = f b / z, reported in 1/disparity_subpixel pixel steps.
        const double steps = std::round(fb / z * config_.disparity_subpixel);
        if (steps <= 0.0) continue;
        z = fb * config_.disparity_subpixel / steps;
      }
      const Vector3d q = z * rays_[i];
      out.cloud.points[i] = q.cast<float>();
      out.labels.data[i] = static_cast<std::uint16_t>(local[static_cast<std::size_t>(hits[i].prim)].label);
    }
    return out;
  }

 protected:
  PixelBox Cull(const Primitive& p) const override {
    // Bounding box of the projection of the hull clipped to z >= z_near: the clipped hull's
    // corners are hull points in front and crossings of segments between hull points.
    constexpr double kNear = 1e-9;
    const PinholeIntrinsics& K = config_.intrinsics;
    double umin = std::numeric_limits<double>::infinity(), umax = -umin, vmin = umin, vmax = -umin;
    bool any = false;
    auto add = [&](const Vector3d& q) {
      const double u = K.fx * q.x() / q.z() + K.cx, v = K.fy * q.y() / q.z() + K.cy;
      umin = std::min(umin, u);
      umax = std::max(umax, u);
      vmin = std::min(vmin, v);
      vmax = std::max(vmax, v);
      any = true;
    };
    const auto& h = p.hull;
    for (std::size_t a = 0; a < h.size(); ++a) {
      if (h[a].z() >= kNear) add(h[a]);
      for (std::size_t b = a + 1; b < h.size(); ++b) {
        if ((h[a].z() < kNear) != (h[b].z() < kNear)) {
          const double t = (kNear - h[a].z()) / (h[b].z() - h[a].z());
          Vector3d q = h[a] + t * (h[b] - h[a]);
          q.z() = kNear;
          add(q);
        }
      }
    }
    PixelBox box;
    if (!any) return box;
    auto clampi = [](double x, int lo, int hi) {
      if (!(x > lo)) return lo;  // also NaN
      if (x > hi) return hi;
      return static_cast<int>(x);
    };
    box.c0 = clampi(std::floor(umin) - 1, 0, width_ - 1);
    box.c1 = clampi(std::ceil(umax) + 1, 0, width_ - 1);
    box.r0 = clampi(std::floor(vmin) - 1, 0, height_ - 1);
    box.r1 = clampi(std::ceil(vmax) + 1, 0, height_ - 1);
    if (umax < -1 || umin > width_ || vmax < -1 || vmin > height_) box = PixelBox{};
    return box;
  }

 private:
  static constexpr std::size_t kMaxEdges = 16;
  PinholeSimConfig config_;
  std::vector<double> xs_, ys_;  // normalised image coordinates of columns and rows
};

/// Spherical scanner.
class SphericalCaster final : public CasterBase {
 public:
  SphericalCaster(const SyntheticScene& scene, const SphericalSimConfig& config)
      : CasterBase(scene, config.Width(), config.Height()), config_(config) {
    PLANESLAM_CHECK(width_ > 0 && height_ > 0, "bad spherical scanner geometry");
    for (int r = 0; r < height_; ++r) {
      const double el = Elevation(r);
      for (int c = 0; c < width_; ++c) {
        const double az = Azimuth(c);
        const std::size_t i = static_cast<std::size_t>(r) * width_ + c;
        rays_[i] = Vector3d(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az),
                            std::sin(el));
        ray_norm2_[i] = 1.0;
        ray_norm_[i] = 1.0;
      }
    }
  }
  SensorModel Model() const override { return SensorModel::kSpherical; }

  SyntheticRender Render(const Pose& T_world_sensor, std::uint64_t noise_seed) const override {
    // Per-thread scratch, reused across frames (saves ~5 MB of fresh pages per frame).
    thread_local std::vector<Hit> hits;
    thread_local std::vector<Primitive> local;
    Cast(T_world_sensor, hits, local, config_.max_range);
    SyntheticRender out;
    out.cloud = OrganizedCloud(width_, height_, SensorModel::kSpherical);
    out.labels = Image16(width_, height_);
    out.true_range.assign(hits.size(), std::numeric_limits<float>::quiet_NaN());
    const double cos_max = std::cos(config_.max_incidence_deg * kDeg);
    SplitMixRandom rng(noise_seed);
    for (std::size_t i = 0; i < hits.size(); ++i) {
      const Hit& h = hits[i];
      if (h.prim < 0) continue;
      out.true_range[i] = static_cast<float>(h.s);
      if (h.s < config_.min_range || h.s > config_.max_range) continue;
      const Vector3d& D = rays_[i];
      const Primitive& p = local[static_cast<std::size_t>(h.prim)];
      if (std::abs(NormalAt(p, h.s * D).dot(D)) < cos_max) continue;
      if (config_.dropout_rate > 0.0 && rng.Uniform() < config_.dropout_rate) continue;
      double range = h.s;
      if (config_.noise) range += config_.range_sigma * rng.TruncatedNormal(config_.noise_truncation);
      out.cloud.points[i] = (range * D).cast<float>();
      out.labels.data[i] = static_cast<std::uint16_t>(p.label);
    }
    return out;
  }

 protected:
  bool WrapColumns() const override { return config_.azimuth_fov_deg >= 360.0 - 1e-9; }

  double Elevation(int r) const {
    return (config_.elevation_max_deg - r * config_.elevation_resolution_deg) * kDeg;
  }
  double Azimuth(int c) const {
    return (0.5 * config_.azimuth_fov_deg - (c + 0.5) * config_.azimuth_resolution_deg) * kDeg;
  }

  PixelBox Cull(const Primitive& p) const override {
    PixelBox all{0, height_ - 1, 0, width_ - 1};
    const double dist = p.bs_center.norm();
    if (dist <= p.bs_radius * (1.0 + 1e-9) + 1e-12) return all;
    const double alpha = std::asin(std::min(1.0, p.bs_radius / dist));
    const double el = std::asin(std::clamp(p.bs_center.z() / dist, -1.0, 1.0));
    const double res_el = config_.elevation_resolution_deg * kDeg;
    const double res_az = config_.azimuth_resolution_deg * kDeg;
    const double el_max = config_.elevation_max_deg * kDeg;
    // Row r has elevation el_max - r * res_el.
    PixelBox box;
    box.r0 = std::max(0, static_cast<int>(std::floor((el_max - (el + alpha)) / res_el)) - 1);
    box.r1 = std::min(height_ - 1,
                      static_cast<int>(std::ceil((el_max - (el - alpha)) / res_el)) + 1);
    if (box.r0 > box.r1) return PixelBox{};
    if (std::abs(el) + alpha >= 0.5 * kPi - 1e-9) {
      box.c0 = 0;
      box.c1 = width_ - 1;
      return box;
    }
    // Azimuth half-width of a cone of half-angle alpha at elevation el: sin(daz) =
    // sin(alpha) / cos(el) (the right-ascension extent of a small circle).
    const double daz = std::asin(std::min(1.0, std::sin(alpha) / std::cos(el)));
    const double az = std::atan2(p.bs_center.y(), p.bs_center.x());
    const double half_fov = 0.5 * config_.azimuth_fov_deg * kDeg;
    // Column c has azimuth half_fov - (c + 0.5) * res_az.
    int c0 = static_cast<int>(std::floor((half_fov - (az + daz)) / res_az - 0.5)) - 1;
    int c1 = static_cast<int>(std::ceil((half_fov - (az - daz)) / res_az - 0.5)) + 1;
    if (WrapColumns()) {
      if (c1 - c0 + 1 >= width_) {
        c0 = 0;
        c1 = width_ - 1;
      }
    } else {
      // The cone may also reach columns on the other side of +-180 degrees.
      if (az + daz > kPi || az - daz < -kPi) {
        c0 = 0;
        c1 = width_ - 1;
      }
      c0 = std::max(c0, 0);
      c1 = std::min(c1, width_ - 1);
    }
    box.c0 = c0;
    box.c1 = c1;
    return box;
  }

 private:
  SphericalSimConfig config_;
};

}  // namespace

int SphericalSimConfig::Width() const {
  return static_cast<int>(std::lround(azimuth_fov_deg / azimuth_resolution_deg));
}
int SphericalSimConfig::Height() const {
  return static_cast<int>(
             std::lround((elevation_max_deg - elevation_min_deg) / elevation_resolution_deg)) +
         1;
}

std::unique_ptr<SyntheticSensor> MakePinholeSensor(const SyntheticScene& scene,
                                                   const PinholeSimConfig& config) {
  return std::make_unique<PinholeCaster>(scene, config);
}

std::unique_ptr<SyntheticSensor> MakeSphericalSensor(const SyntheticScene& scene,
                                                     const SphericalSimConfig& config) {
  return std::make_unique<SphericalCaster>(scene, config);
}

Eigen::Matrix3d BodyFromOptical() {
  // Columns: the optical axes expressed in the body (forward-left-up) frame.
  Eigen::Matrix3d R;
  R.col(0) = -Vector3d::UnitY();  // optical x = right
  R.col(1) = -Vector3d::UnitZ();  // optical y = down
  R.col(2) = Vector3d::UnitX();   // optical z = forward
  return R;
}

}  // namespace planeslam::datasets
