#pragma once
// SceneBuilder: appends planar faces, boxes, spheres and cylinders to a SyntheticScene with plane
// ids 1..N in order of creation. Shared by the scene builders of datasets/sim (private header).
#include <cmath>
#include <string>
#include <utility>
#include <vector>

#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/synthetic_scene.hpp"

namespace planeslam::datasets::detail {

using Eigen::Vector3d;

/// Appends plane pieces; keeps ids = index + 1.
class SceneBuilder {
 public:
  explicit SceneBuilder(std::string name) { scene_.name = std::move(name); }

  /// New plane from its first convex piece (corners CCW seen from the normal side).
  int AddPolygon(const std::string& name, std::vector<Vector3d> corners) {
    ScenePlane plane;
    plane.id = static_cast<int>(scene_.planes.size()) + 1;
    plane.name = name;
    plane.normal = NewellNormal(corners);
    plane.d = plane.normal.dot(Centroid(corners));
    plane.polygons.push_back(std::move(corners));
    scene_.planes.push_back(std::move(plane));
    return scene_.planes.back().id;
  }
  /// Another convex piece of an existing plane (must lie in it).
  void AddPiece(int id, std::vector<Vector3d> corners) {
    ScenePlane& plane = scene_.planes[static_cast<std::size_t>(id - 1)];
    for (const Vector3d& c : corners) {
      PLANESLAM_CHECK(std::abs(plane.normal.dot(c) - plane.d) < 1e-9, "piece off plane " << id);
    }
    PLANESLAM_CHECK(NewellNormal(corners).dot(plane.normal) > 0.999, "piece flipped " << id);
    plane.polygons.push_back(std::move(corners));
  }
  /// Rectangle centre +- u +- v; normal u x v.
  int AddRect(const std::string& name, const Vector3d& c, const Vector3d& u, const Vector3d& v) {
    return AddPolygon(name, {c - u - v, c + u - v, c + u + v, c - u + v});
  }
  static std::vector<Vector3d> Rect(const Vector3d& c, const Vector3d& u, const Vector3d& v) {
    return {c - u - v, c + u - v, c + u + v, c - u + v};
  }
  /// Disk face with outward normal n.
  int AddDisk(const std::string& name, const Vector3d& center, const Vector3d& n, double r) {
    ScenePlane plane;
    plane.id = static_cast<int>(scene_.planes.size()) + 1;
    plane.name = name;
    plane.normal = n.normalized();
    plane.d = plane.normal.dot(center);
    plane.is_disk = true;
    plane.disk_center = center;
    plane.disk_radius = r;
    const Vector3d a = AnyPerpendicular(plane.normal);
    const Vector3d b = plane.normal.cross(a);
    std::vector<Vector3d> outline;
    for (int k = 0; k < 32; ++k) {
      const double phi = 2.0 * 3.14159265358979323846 * k / 32.0;
      outline.push_back(center + r * (std::cos(phi) * a + std::sin(phi) * b));
    }
    plane.polygons.push_back(std::move(outline));
    scene_.planes.push_back(std::move(plane));
    return scene_.planes.back().id;
  }

  /// Box with yaw about z; `omit` is a bitmask of faces not to create (faces hidden by contact):
  /// 1 = bottom, 2 = top, 4 = -x, 8 = +x, 16 = -y, 32 = +y (in the box's own axes).
  void AddBox(const std::string& name, const Vector3d& center, const Vector3d& size, double yaw,
              int omit) {
    const Vector3d ex(std::cos(yaw), std::sin(yaw), 0.0);
    const Vector3d ey(-std::sin(yaw), std::cos(yaw), 0.0);
    const Vector3d ez = Vector3d::UnitZ();
    const Vector3d hx = 0.5 * size.x() * ex, hy = 0.5 * size.y() * ey, hz = 0.5 * size.z() * ez;
    // Each face: centre offset and two half-axes with u x v = outward normal.
    if (!(omit & 1)) AddRect(name + ".bottom", center - hz, hy, hx);
    if (!(omit & 2)) AddRect(name + ".top", center + hz, hx, hy);
    if (!(omit & 4)) AddRect(name + ".-x", center - hx, hz, hy);
    if (!(omit & 8)) AddRect(name + ".+x", center + hx, hy, hz);
    if (!(omit & 16)) AddRect(name + ".-y", center - hy, hx, hz);
    if (!(omit & 32)) AddRect(name + ".+y", center + hy, hz, hx);
  }

  void AddSphere(const Vector3d& c, double r) { scene_.spheres.push_back({c, r}); }
  void AddCylinder(const std::string& name, const Vector3d& base, const Vector3d& axis,
                   double length, double radius, bool base_cap, bool top_cap) {
    SceneCylinder cyl;
    cyl.base = base;
    cyl.axis = axis.normalized();
    cyl.length = length;
    cyl.radius = radius;
    if (base_cap) cyl.base_cap_id = AddDisk(name + ".cap0", base, -cyl.axis, radius);
    if (top_cap) {
      cyl.top_cap_id = AddDisk(name + ".cap1", base + length * cyl.axis, cyl.axis, radius);
    }
    scene_.cylinders.push_back(cyl);
  }

  SyntheticScene Take() { return std::move(scene_); }

  static Vector3d AnyPerpendicular(const Vector3d& n) {
    const Vector3d t = std::abs(n.x()) < 0.9 ? Vector3d::UnitX() : Vector3d::UnitY();
    return n.cross(t).normalized();
  }

 private:
  static Vector3d NewellNormal(const std::vector<Vector3d>& c) {
    Vector3d n = Vector3d::Zero();
    for (std::size_t i = 0; i < c.size(); ++i) n += c[i].cross(c[(i + 1) % c.size()]);
    PLANESLAM_CHECK(n.norm() > 1e-12, "degenerate polygon");
    return n.normalized();
  }
  static Vector3d Centroid(const std::vector<Vector3d>& c) {
    Vector3d s = Vector3d::Zero();
    for (const Vector3d& p : c) s += p;
    return s / static_cast<double>(c.size());
  }

  SyntheticScene scene_;
};

}  // namespace planeslam::datasets::detail
