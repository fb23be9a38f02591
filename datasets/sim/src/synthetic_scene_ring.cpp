// The aliasing scene: an octagonal ring corridor of eight identical segments.
#include "synthetic_scene_ring.hpp"

#include <cmath>

#include "planeslam/datasets/errors.hpp"

namespace planeslam::datasets {
namespace {

using Eigen::Vector3d;
constexpr double kPi = 3.14159265358979323846;

Vector3d NewellNormal(const std::vector<Vector3d>& c) {
  Vector3d n = Vector3d::Zero();
  for (std::size_t i = 0; i < c.size(); ++i) n += c[i].cross(c[(i + 1) % c.size()]);
  PLANESLAM_CHECK(n.norm() > 1e-12, "degenerate polygon");
  return n.normalized();
}

/// Appends planes (ids = index + 1) made of convex pieces, corners counter-clockwise seen from
/// the side meant to be seen.
class RingBuilder {
 public:
  RingBuilder() { scene_.name = "ring"; }
  int AddPlane(const std::string& name, std::vector<Vector3d> corners) {
    ScenePlane plane;
    plane.id = static_cast<int>(scene_.planes.size()) + 1;
    plane.name = name;
    plane.normal = NewellNormal(corners);
    plane.d = plane.normal.dot(corners.front());
    plane.polygons.push_back(std::move(corners));
    scene_.planes.push_back(std::move(plane));
    return scene_.planes.back().id;
  }
  void AddPiece(int id, std::vector<Vector3d> corners) {
    ScenePlane& plane = scene_.planes[static_cast<std::size_t>(id - 1)];
    PLANESLAM_CHECK(NewellNormal(corners).dot(plane.normal) > 0.999, "piece flipped " << id);
    plane.polygons.push_back(std::move(corners));
  }
  /// Rectangle centre +- u +- v, normal u x v.
  int AddRect(const std::string& name, const Vector3d& c, const Vector3d& u, const Vector3d& v) {
    return AddPlane(name, Rect(c, u, v));
  }
  static std::vector<Vector3d> Rect(const Vector3d& c, const Vector3d& u, const Vector3d& v) {
    return {c - u - v, c + u - v, c + u + v, c - u + v};
  }
  SyntheticScene Take() { return std::move(scene_); }

 private:
  SyntheticScene scene_;
};

}  // namespace

SyntheticScene MakeRingCorridor() {
  constexpr int kSegments = 8;
  const double inner = 1.2, outer = 2.4, H = 2.6;  // apothems and height [m]
  const double half = kPi / kSegments;             // half the angle of a segment
  RingBuilder b;
  const Vector3d uz = Vector3d::UnitZ();
  int floor = 0, ceiling = 0;
  for (int k = 0; k < kSegments; ++k) {
    const double angle = 2.0 * kPi * k / kSegments;
    const Vector3d radial(std::cos(angle), std::sin(angle), 0.0);  // segment's outward normal
    const Vector3d along(-std::sin(angle), std::cos(angle), 0.0);  // counter-clockwise
    const double inner_half = inner * std::tan(half), outer_half = outer * std::tan(half);
    const std::string name = "segment" + std::to_string(k);
    // Floor and ceiling: one plane each, a trapezoid per segment.
    const std::vector<Vector3d> trapezoid = {
        inner * radial - inner_half * along, outer * radial - outer_half * along,
        outer * radial + outer_half * along, inner * radial + inner_half * along};
    if (k == 0) {
      floor = b.AddPlane("floor", trapezoid);
    } else {
      b.AddPiece(floor, trapezoid);
    }
    std::vector<Vector3d> top(trapezoid.rbegin(), trapezoid.rend());
    for (Vector3d& p : top) p.z() = H;
    if (k == 0) {
      ceiling = b.AddPlane("ceiling", top);
    } else {
      b.AddPiece(ceiling, top);
    }
    // Inner wall (faces outwards) with a box against it.
    b.AddRect(name + ".inner", inner * radial + (H / 2) * uz, inner_half * along, (H / 2) * uz);
    const Vector3d box = (inner + 0.2) * radial + 0.25 * uz;
    b.AddRect(name + ".box.front", box + 0.2 * radial, 0.4 * along, 0.25 * uz);
    b.AddRect(name + ".box.top", box + 0.25 * uz, 0.2 * radial, 0.4 * along);
    b.AddRect(name + ".box.side0", box - 0.4 * along, 0.2 * radial, 0.25 * uz);
    b.AddRect(name + ".box.side1", box + 0.4 * along, 0.25 * uz, 0.2 * radial);
    // Outer wall (faces inwards) with a door recess 0.9 m wide, 2.1 m high, 0.2 m deep.
    const double door = 0.45, hd = 2.1, depth = 0.2;
    const Vector3d wall = outer * radial;
    const double side = (outer_half - door) / 2;
    const int outer_wall = b.AddRect(name + ".outer", wall - (door + side) * along + (H / 2) * uz,
                                     (H / 2) * uz, side * along);
    b.AddPiece(outer_wall, RingBuilder::Rect(wall + (door + side) * along + (H / 2) * uz,
                                             (H / 2) * uz, side * along));
    b.AddPiece(outer_wall,
               RingBuilder::Rect(wall + ((hd + H) / 2) * uz, ((H - hd) / 2) * uz, door * along));
    b.AddRect(name + ".door", wall + depth * radial + (hd / 2) * uz, (hd / 2) * uz, door * along);
    b.AddRect(name + ".jamb0", wall + (depth / 2) * radial - door * along + (hd / 2) * uz,
              (hd / 2) * uz, (depth / 2) * radial);
    b.AddRect(name + ".jamb1", wall + (depth / 2) * radial + door * along + (hd / 2) * uz,
              (depth / 2) * radial, (hd / 2) * uz);
    b.AddRect(name + ".head", wall + (depth / 2) * radial + hd * uz, door * along,
              (depth / 2) * radial);
  }
  return b.Take();
}

}  // namespace planeslam::datasets
