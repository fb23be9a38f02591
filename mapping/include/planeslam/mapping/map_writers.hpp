#pragma once
/// Plane map files: a triangle mesh of the plane outlines (PLY, OBJ), a JSON description of every
/// plane, and a coloured point PLY for debugging. Pure file output; every file is written to a
/// temporary name and renamed into place (AtomicOutputFile), IoError naming the file on failure.
///
/// Formats:
///  - plane_map.ply: binary_little_endian (or ascii) 1.0, `element vertex` (float x y z, uchar red
///    green blue), `element face` (list uchar int vertex_indices): the ear-clipped outline parts of
///    each plane, all their vertices in the plane's colour. Opens in MeshLab, CloudCompare, PCL.
///  - plane_map.obj: `o plane_<id>` per plane, `v x y z r g b` (colour in [0, 1], the extension
///    MeshLab and CloudCompare read; other readers ignore the extra numbers), `f a b c` (1-based).
///  - plane_map.json: {"format": "planeslam-plane-map", "version": 2, "frame": "world",
///    "planes": [{id, normal, d, centroid, area, observed_area, point_count, rms, observations,
///    first_frame, last_frame, color, polygons: [[[x, y, z], ...], ...]}]} (metres; the normal
///    points away from the sensors that saw the plane; one polygon per separate part of the plane,
///    largest first, each counter-clockwise about the normal; area is their sum). Version 1 files
///    carry a single "polygon" instead (the largest part only).
/// Mesh faces are wound counter-clockwise as seen by the observers (right-hand face normal =
/// -normal), so viewers with back-face culling show each plane from the side it was seen from.
#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "planeslam/mapping/plane_map.hpp"

namespace planeslam::mapping {

using Rgb8 = std::array<std::uint8_t, 3>;

/// Everything the writers need about one map plane (decoupled from PlaneMap so that any plane set,
/// e.g. ground truth, can be written the same way).
struct MapPlaneRecord {
  int id = 0;
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();   ///< unit, world
  double d = 0.0;                                      ///< n . p = d [m]
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();  ///< [m]
  /// Outline: one polygon per separate part, world [m]; empty when the plane has no outline.
  std::vector<std::vector<Eigen::Vector3d>> polygons;
  /// Per part: triangles as indices into that part's polygon.
  std::vector<std::vector<std::array<int, 3>>> triangles;
  double area = 0.0;           ///< outline area, all parts [m^2]
  double observed_area = 0.0;  ///< observed area (holes excluded) [m^2]
  std::int64_t point_count = 0;
  double rms = 0.0;  ///< sqrt(mse) of the fit [m]
  int observations = 0;
  std::int64_t first_frame = 0;  ///< keyframe ids
  std::int64_t last_frame = 0;
  Rgb8 color{200, 200, 200};
};

/// A distinct, deterministic colour per plane id (golden-ratio hue steps, full saturation).
Rgb8 PlaneColor(int id);

/// Records of the planes of `map` with their outlines (PlaneMap::Outline) and PlaneColor colours,
/// leaving out planes seen fewer than `min_observations` times or with an outline area below
/// `min_area` [m^2] (single noisy detections of far surfaces clutter a map).
std::vector<MapPlaneRecord> MakeMapRecords(const PlaneMap& map, int min_observations = 1,
                                           double min_area = 0.0);

enum class PlyFormat { kBinary, kAscii };

/// Triangulated outlines as a coloured mesh (planes without a polygon are left out).
void WritePlaneMapPly(const std::string& path, const std::vector<MapPlaneRecord>& planes,
                      PlyFormat format = PlyFormat::kBinary);
/// Same mesh as OBJ with per-vertex colours and one object per plane.
void WritePlaneMapObj(const std::string& path, const std::vector<MapPlaneRecord>& planes);
/// Every plane (also those without a polygon) with its parameters and outline.
void WritePlaneMapJson(const std::string& path, const std::vector<MapPlaneRecord>& planes);

/// Points with one colour each (colors.size() == points.size(), or empty for white); non-finite
/// points are skipped.
void WriteColoredPointsPly(const std::string& path, const std::vector<Eigen::Vector3f>& points,
                           const std::vector<Rgb8>& colors, PlyFormat format = PlyFormat::kBinary);

}  // namespace planeslam::mapping
