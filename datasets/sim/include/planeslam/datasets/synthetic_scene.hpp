#pragma once
/// Synthetic worlds made of analytic primitives with exact ground truth (world frame, z up, metres).
///
/// A scene is a list of planar faces (each with a plane id 1..N, unique in the scene), spheres and
/// finite cylinders. Curved surfaces carry no plane id (label 0); a cylinder's flat end caps are
/// planar faces with their own ids. Scenes are built deterministically: `room` and `corridor` are
/// fixed, `rubble` is drawn from the seed.
#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cstdint>
#include <string>
#include <vector>

namespace planeslam::datasets {

/// The built-in worlds.
enum class SceneKind {
  kRoom,      ///< office-like room (6 x 5 x 2.8 m): walls, floor, ceiling, table, boxes, door recess
  kCorridor,  ///< 30 m corridor, open ends: plane registration cannot observe motion along x
  kRubble,    ///< small tilted slabs, spheres and cylinders on a ground plane: unstructured
  kStreet,    ///< urban block for LiDAR (synthetic_street.hpp)
};

/// "room", "corridor", "rubble", "street".
std::string SceneName(SceneKind kind);
/// Inverse of SceneName; throws ConfigError naming the accepted values.
SceneKind ParseSceneKind(const std::string& name);

/// One planar face. Its extent is a union of convex polygons lying in the plane n.p = d, or a disk.
struct ScenePlane {
  int id = 0;                  ///< plane id, 1..N (also its label in label images)
  std::string name;            ///< e.g. "floor", "table.top", "slab12"
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  ///< unit, pointing to the side meant to be seen
  double d = 0.0;              ///< offset [m]: points p of the plane satisfy normal.p = d
  /// Convex pieces, corners counter-clockwise seen from the normal side [m]. For a disk: a
  /// 32-gon outline, for display only (the exact extent is the disk).
  std::vector<std::vector<Eigen::Vector3d>> polygons;
  bool is_disk = false;                              ///< true: extent is the disk below
  Eigen::Vector3d disk_center = Eigen::Vector3d::Zero();  ///< [m]
  double disk_radius = 0.0;                          ///< [m]

  /// Area of the exact extent [m^2].
  double Area() const;
};

/// Sphere (clutter, label 0).
struct SceneSphere {
  Eigen::Vector3d center = Eigen::Vector3d::Zero();  ///< [m]
  double radius = 0.1;                               ///< [m]
};

/// Finite cylinder: lateral surface (label 0) between base and base + length * axis; each end is
/// closed by a disk face whose plane id is given, or open when the id is 0.
struct SceneCylinder {
  Eigen::Vector3d base = Eigen::Vector3d::Zero();  ///< centre of the first end [m]
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();  ///< unit
  double length = 1.0;                             ///< [m]
  double radius = 0.1;                             ///< [m]
  int base_cap_id = 0;                             ///< plane id of the disk at `base`, 0 = open
  int top_cap_id = 0;                              ///< plane id of the disk at the other end
};

/// A whole world.
struct SyntheticScene {
  std::string name;
  std::vector<ScenePlane> planes;  ///< planes[k - 1].id == k
  std::vector<SceneSphere> spheres;
  std::vector<SceneCylinder> cylinders;

  /// The plane with id `id` (1..N); throws CheckError when there is none.
  const ScenePlane& Plane(int id) const;
  /// Axis-aligned bounds of everything [m].
  Eigen::AlignedBox3d Bounds() const;
};

/// Builds scene `kind`. `seed` only matters for rubble (layout of the pieces) and street
/// (buildings, cars and furniture).
SyntheticScene MakeScene(SceneKind kind, std::uint64_t seed = 1);

/// Exact nearest intersection of a ray with a scene (the reference the fast casters are tested
/// against, and a convenience for single rays; far too slow for whole images).
struct RayHit {
  bool hit = false;
  double t = 0.0;                                   ///< distance along the (unit) direction [m]
  int label = 0;                                    ///< plane id, 0 for curved surfaces
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();  ///< surface normal at the hit (unit)
};
/// Nearest hit with t > 0 of the ray origin + t * direction (direction unit), over all primitives.
RayHit IntersectScene(const SyntheticScene& scene, const Eigen::Vector3d& origin,
                      const Eigen::Vector3d& direction);

}  // namespace planeslam::datasets
