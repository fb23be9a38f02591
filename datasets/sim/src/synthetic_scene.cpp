// Scene construction (room, corridor, rubble) and the brute-force reference ray intersection.
#include <cmath>
#include <random>

#include "planeslam/datasets/errors.hpp"
#include "scene_builder.hpp"
#include "synthetic_random.hpp"
#include "planeslam/datasets/synthetic_scene.hpp"
#include "planeslam/datasets/synthetic_street.hpp"

namespace planeslam::datasets {

namespace {

using detail::SceneBuilder;
using Eigen::Vector3d;
constexpr double kPi = 3.14159265358979323846;

// Room: x in [-3, 3], y in [-2.5, 2.5], z in [0, 2.8]; normals of the shell point inwards.
SyntheticScene MakeRoom() {
  const double X = 3.0, Y = 2.5, H = 2.8;
  SceneBuilder b("room");
  const Vector3d ux = Vector3d::UnitX(), uy = Vector3d::UnitY(), uz = Vector3d::UnitZ();
  const int floor = b.AddRect("floor", Vector3d(0, 0, 0), X * ux, Y * uy);
  b.AddRect("ceiling", Vector3d(0, 0, H), Y * uy, X * ux);
  b.AddRect("wall.+y", Vector3d(0, Y, H / 2), X * ux, (H / 2) * uz);
  b.AddRect("wall.-y", Vector3d(0, -Y, H / 2), (H / 2) * uz, X * ux);
  b.AddRect("wall.-x", Vector3d(-X, 0, H / 2), Y * uy, (H / 2) * uz);
  // Wall +x with a door opening y in [0.35, 1.25], z in [0, 2.1]: three convex pieces.
  const double y0 = 0.35, y1 = 1.25, hd = 2.1, depth = 0.2;
  const int wall_x = b.AddPolygon(
      "wall.+x", SceneBuilder::Rect(Vector3d(X, (-Y + y0) / 2, H / 2), (H / 2) * uz,
                                    ((y0 + Y) / 2) * uy));
  b.AddPiece(wall_x, SceneBuilder::Rect(Vector3d(X, (y1 + Y) / 2, H / 2), (H / 2) * uz,
                                        ((Y - y1) / 2) * uy));
  b.AddPiece(wall_x, SceneBuilder::Rect(Vector3d(X, (y0 + y1) / 2, (hd + H) / 2),
                                        ((H - hd) / 2) * uz, ((y1 - y0) / 2) * uy));
  // Door recess: the door 0.2 m behind the wall, two jambs, the head, and the floor continues.
  b.AddRect("door", Vector3d(X + depth, (y0 + y1) / 2, hd / 2), (hd / 2) * uz,
            ((y1 - y0) / 2) * uy);
  b.AddRect("door.jamb0", Vector3d(X + depth / 2, y0, hd / 2), (hd / 2) * uz, (depth / 2) * ux);
  b.AddRect("door.jamb1", Vector3d(X + depth / 2, y1, hd / 2), (depth / 2) * ux, (hd / 2) * uz);
  b.AddRect("door.head", Vector3d(X + depth / 2, (y0 + y1) / 2, hd), ((y1 - y0) / 2) * uy,
            (depth / 2) * ux);
  b.AddPiece(floor, SceneBuilder::Rect(Vector3d(X + depth / 2, (y0 + y1) / 2, 0),
                                       (depth / 2) * ux, ((y1 - y0) / 2) * uy));
  // Table: 1.4 x 0.7 x 0.04 top at 0.75 m on four round legs.
  const Vector3d table(-1.7, 1.6, 0.73);
  b.AddBox("table", table, Vector3d(1.4, 0.7, 0.04), 0.0, 0);
  for (int i = 0; i < 4; ++i) {
    const double sx = (i & 1) ? 1.0 : -1.0, sy = (i & 2) ? 1.0 : -1.0;
    b.AddCylinder("table.leg" + std::to_string(i),
                  Vector3d(table.x() + sx * 0.62, table.y() + sy * 0.27, 0.0), uz, 0.71, 0.025,
                  false, false);
  }
  // Boxes on the floor (bottoms hidden), one stacked, a cabinet against wall -x (back hidden).
  b.AddBox("box0", Vector3d(2.2, -1.8, 0.25), Vector3d(0.6, 0.4, 0.5), 20.0 * kPi / 180, 1);
  b.AddBox("box1", Vector3d(-2.3, -1.8, 0.45), Vector3d(0.8, 0.6, 0.9), 0.0, 1);
  b.AddBox("box2", Vector3d(-2.35, -1.75, 1.05), Vector3d(0.4, 0.4, 0.3), 35.0 * kPi / 180, 1);
  b.AddBox("cabinet", Vector3d(-2.75, -0.2, 0.9), Vector3d(0.5, 1.2, 1.8), 0.0, 1 | 4);
  // Whiteboard on wall +y: 2 cm thick, back against the wall.
  b.AddBox("whiteboard", Vector3d(0.3, Y - 0.01, 1.5), Vector3d(1.2, 0.02, 0.8), 0.0, 32);
  // Curved clutter: a ball on the floor and a round stool.
  b.AddSphere(Vector3d(1.2, -2.0, 0.15), 0.15);
  b.AddCylinder("stool", Vector3d(2.4, 1.9, 0.0), uz, 0.45, 0.18, false, true);
  return b.Take();
}

// Corridor along x: x in [0, 30], y in [-1, 1], z in [0, 2.6], open ends. Cross structures are
// curved only (pipes under the ceiling, lamps), so every planar face has a normal orthogonal to x.
SyntheticScene MakeCorridor() {
  const double L = 30.0, W = 1.0, H = 2.6;
  SceneBuilder b("corridor");
  const Vector3d ux = Vector3d::UnitX(), uy = Vector3d::UnitY(), uz = Vector3d::UnitZ();
  b.AddRect("floor", Vector3d(L / 2, 0, 0), (L / 2) * ux, W * uy);
  b.AddRect("ceiling", Vector3d(L / 2, 0, H), W * uy, (L / 2) * ux);
  b.AddRect("wall.+y", Vector3d(L / 2, W, H / 2), (L / 2) * ux, (H / 2) * uz);
  b.AddRect("wall.-y", Vector3d(L / 2, -W, H / 2), (H / 2) * uz, (L / 2) * ux);
  for (int k = 0; k < 5; ++k) {
    const double x = 4.0 + 6.0 * k;
    b.AddCylinder("pipe" + std::to_string(k), Vector3d(x, -W, H - 0.15), uy, 2 * W, 0.06, false,
                  false);
    b.AddSphere(Vector3d(x + 3.0, 0.0, H - 0.25), 0.12);
  }
  // A handrail along the corridor on wall -y (axis along x: constrains nothing along x).
  b.AddCylinder("handrail", Vector3d(0.0, -W + 0.06, 0.9), ux, L, 0.025, false, false);
  return b.Take();
}

// Rubble: a 14 x 14 m ground plane and a pile of tilted slabs, balls and lying cylinders within
// 2.5 m of the origin (the camera circles at 3.8 m, clear of everything).
SyntheticScene MakeRubble(std::uint64_t seed) {
  SceneBuilder b("rubble");
  SplitMixRandom rng(seed ^ 0x52554242ULL);  // "RUBB": rubble layout independent of sensor noise
  b.AddRect("ground", Vector3d::Zero(), 7.0 * Vector3d::UnitX(), 7.0 * Vector3d::UnitY());
  const int kSlabs = 40;
  for (int i = 0; i < kSlabs; ++i) {
    const double rho = 2.3 * std::sqrt(rng.Uniform());
    const double phi = 2 * kPi * rng.Uniform();
    const Vector3d c(rho * std::cos(phi), rho * std::sin(phi), rng.Uniform(0.1, 0.8));
    // Normal tilted 10..70 degrees from vertical, random azimuth.
    const double tilt = rng.Uniform(10.0, 70.0) * kPi / 180.0;
    const double az = 2 * kPi * rng.Uniform();
    const Vector3d n(std::sin(tilt) * std::cos(az), std::sin(tilt) * std::sin(az),
                     std::cos(tilt));
    const Vector3d a = SceneBuilder::AnyPerpendicular(n);
    const Vector3d bb = n.cross(a);
    const double spin = 2 * kPi * rng.Uniform();
    const Vector3d u = std::cos(spin) * a + std::sin(spin) * bb;
    const Vector3d v = n.cross(u);
    const std::string name = "slab" + std::to_string(i);
    if (rng.Uniform() < 0.6) {
      const double sa = rng.Uniform(0.3, 1.5), sb = rng.Uniform(0.3, 1.5);
      b.AddRect(name, c, 0.5 * sa * u, 0.5 * sb * v);
    } else {
      // Convex polygon: 5..7 corners at increasing angles on an ellipse-ish outline (convex
      // because all corners lie on one ellipse).
      const int m = 5 + static_cast<int>(rng.Uniform() * 3.0);
      const double ra = rng.Uniform(0.15, 0.75), rb = rng.Uniform(0.15, 0.75);
      std::vector<double> angles;
      for (int k = 0; k < m; ++k) angles.push_back(2 * kPi * (k + rng.Uniform(0.0, 0.6)) / m);
      std::vector<Vector3d> corners;
      for (double t : angles) corners.push_back(c + ra * std::cos(t) * u + rb * std::sin(t) * v);
      b.AddPolygon(name, corners);
    }
  }
  for (int i = 0; i < 6; ++i) {
    const double rho = 2.5 * std::sqrt(rng.Uniform());
    const double phi = 2 * kPi * rng.Uniform();
    const double r = rng.Uniform(0.15, 0.4);
    b.AddSphere(Vector3d(rho * std::cos(phi), rho * std::sin(phi), 0.6 * r), r);
  }
  for (int i = 0; i < 6; ++i) {
    const double rho = 2.0 * std::sqrt(rng.Uniform());
    const double phi = 2 * kPi * rng.Uniform();
    const double r = rng.Uniform(0.08, 0.2);
    const double len = rng.Uniform(0.6, 1.5);
    const double yaw = 2 * kPi * rng.Uniform();
    const Vector3d axis(std::cos(yaw), std::sin(yaw), 0.0);
    const Vector3d mid(rho * std::cos(phi), rho * std::sin(phi), r);
    b.AddCylinder("cylinder" + std::to_string(i), mid - 0.5 * len * axis, axis, len, r, true,
                  true);
  }
  return b.Take();
}

bool InsideConvex(const std::vector<Vector3d>& poly, const Vector3d& n, const Vector3d& p) {
  for (std::size_t i = 0; i < poly.size(); ++i) {
    const Vector3d& a = poly[i];
    const Vector3d& c = poly[(i + 1) % poly.size()];
    if ((c - a).cross(p - a).dot(n) < 0.0) return false;
  }
  return true;
}

}  // namespace

std::string SceneName(SceneKind kind) {
  switch (kind) {
    case SceneKind::kRoom:
      return "room";
    case SceneKind::kCorridor:
      return "corridor";
    case SceneKind::kRubble:
      return "rubble";
    case SceneKind::kStreet:
      return "street";
  }
  return "room";
}

SceneKind ParseSceneKind(const std::string& name) {
  if (name == "room") return SceneKind::kRoom;
  if (name == "corridor") return SceneKind::kCorridor;
  if (name == "rubble") return SceneKind::kRubble;
  if (name == "street") return SceneKind::kStreet;
  throw ConfigError("unknown synthetic scene '" + name +
                    "' (expected room, corridor, rubble or street)");
}

double ScenePlane::Area() const {
  if (is_disk) return kPi * disk_radius * disk_radius;
  double area = 0.0;
  for (const auto& poly : polygons) {
    Vector3d s = Vector3d::Zero();
    for (std::size_t i = 0; i < poly.size(); ++i) s += poly[i].cross(poly[(i + 1) % poly.size()]);
    area += 0.5 * std::abs(s.dot(normal));
  }
  return area;
}

const ScenePlane& SyntheticScene::Plane(int id) const {
  PLANESLAM_CHECK(id >= 1 && id <= static_cast<int>(planes.size()), "no plane " << id);
  return planes[static_cast<std::size_t>(id - 1)];
}

Eigen::AlignedBox3d SyntheticScene::Bounds() const {
  Eigen::AlignedBox3d box;
  for (const auto& p : planes)
    for (const auto& poly : p.polygons)
      for (const auto& c : poly) box.extend(c);
  for (const auto& s : spheres) {
    box.extend(s.center - Vector3d::Constant(s.radius));
    box.extend(s.center + Vector3d::Constant(s.radius));
  }
  for (const auto& c : cylinders) {
    // The end disks' exact extent: radius * sqrt(1 - axis_i^2) along world axis i.
    const Vector3d ext = (Vector3d::Ones() - c.axis.cwiseAbs2()).cwiseMax(0.0).cwiseSqrt() * c.radius;
    for (const Vector3d& e : {c.base, Vector3d(c.base + c.length * c.axis)}) {
      box.extend(e - ext);
      box.extend(e + ext);
    }
  }
  return box;
}

SyntheticScene MakeScene(SceneKind kind, std::uint64_t seed) {
  switch (kind) {
    case SceneKind::kRoom:
      return MakeRoom();
    case SceneKind::kCorridor:
      return MakeCorridor();
    case SceneKind::kRubble:
      return MakeRubble(seed);
    case SceneKind::kStreet:
      return MakeStreetScene(seed);
  }
  return MakeRoom();
}

RayHit IntersectScene(const SyntheticScene& scene, const Vector3d& o, const Vector3d& d) {
  RayHit best;
  auto consider = [&](double t, int label, const Vector3d& n) {
    if (t > 0.0 && (!best.hit || t < best.t)) {
      best.hit = true;
      best.t = t;
      best.label = label;
      best.normal = n;
    }
  };
  for (const ScenePlane& plane : scene.planes) {
    const double denom = plane.normal.dot(d);
    if (denom == 0.0) continue;
    const double t = (plane.d - plane.normal.dot(o)) / denom;
    if (t <= 0.0) continue;
    const Vector3d p = o + t * d;
    bool inside = false;
    if (plane.is_disk) {
      inside = (p - plane.disk_center).squaredNorm() <= plane.disk_radius * plane.disk_radius;
    } else {
      for (const auto& poly : plane.polygons) inside = inside || InsideConvex(poly, plane.normal, p);
    }
    if (inside) consider(t, plane.id, plane.normal);
  }
  for (const SceneSphere& s : scene.spheres) {
    const Vector3d w = o - s.center;
    const double bq = w.dot(d), c = w.squaredNorm() - s.radius * s.radius;
    const double disc = bq * bq - c;
    if (disc < 0.0) continue;
    const double sq = std::sqrt(disc);
    for (double t : {-bq - sq, -bq + sq}) {
      if (t > 0.0) {
        consider(t, 0, (o + t * d - s.center).normalized());
        break;
      }
    }
  }
  for (const SceneCylinder& c : scene.cylinders) {
    const Vector3d w = o - c.base;
    const Vector3d dp = d - d.dot(c.axis) * c.axis;
    const Vector3d wp = w - w.dot(c.axis) * c.axis;
    const double A = dp.squaredNorm();
    if (A == 0.0) continue;
    const double B = wp.dot(dp), C = wp.squaredNorm() - c.radius * c.radius;
    const double disc = B * B - A * C;
    if (disc < 0.0) continue;
    const double sq = std::sqrt(disc);
    for (double t : {(-B - sq) / A, (-B + sq) / A}) {
      if (t <= 0.0) continue;
      const double h = (w + t * d).dot(c.axis);
      if (h < 0.0 || h > c.length) continue;
      const Vector3d radial = wp + t * dp;
      consider(t, 0, radial.normalized());
      break;
    }
  }
  return best;
}

}  // namespace planeslam::datasets
