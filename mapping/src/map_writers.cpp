#include "planeslam/mapping/map_writers.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ostream>

#include "planeslam/datasets/atomic_file.hpp"
#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/image_io.hpp"

namespace planeslam::mapping {
namespace {

static_assert(sizeof(float) == 4 && sizeof(std::int32_t) == 4, "PLY needs 4-byte float and int");

bool HostIsLittleEndian() {
  const std::uint16_t probe = 1;
  std::uint8_t first = 0;
  std::memcpy(&first, &probe, 1);
  return first == 1;
}

/// Appends the little-endian bytes of a 4-byte value.
template <class T>
void PutLe(std::string& out, T value) {
  static_assert(sizeof(T) == 4, "4-byte values only");
  unsigned char bytes[4];
  std::memcpy(bytes, &value, 4);
  if (!HostIsLittleEndian()) std::reverse(bytes, bytes + 4);
  out.append(reinterpret_cast<const char*>(bytes), 4);
}

/// Shortest text that reads back as the same double (JSON has no NaN/inf: null instead).
std::string Num(double x) {
  if (!std::isfinite(x)) return "null";
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.17g", x);
  // Prefer fewer digits when they round-trip (most values do at 15 significant digits).
  char shorter[32];
  std::snprintf(shorter, sizeof(shorter), "%.15g", x);
  return std::strtod(shorter, nullptr) == x ? shorter : buf;
}

std::string Vec(const Eigen::Vector3d& v) {
  return "[" + Num(v.x()) + ", " + Num(v.y()) + ", " + Num(v.z()) + "]";
}

/// The mesh shared by the PLY and OBJ writers: vertices with colours, triangles wound towards the
/// observers (the records' triangles are counter-clockwise about the normal, so swap two corners).
struct Mesh {
  std::vector<Eigen::Vector3f> vertices;
  std::vector<Rgb8> colors;
  std::vector<std::array<int, 3>> faces;
  std::vector<std::pair<int, std::size_t>> objects;  ///< plane id, index of its first face
};

Mesh BuildMesh(const std::vector<MapPlaneRecord>& planes) {
  Mesh mesh;
  for (const auto& p : planes) {
    PLANESLAM_CHECK(p.triangles.size() == p.polygons.size(),
                    "plane " << p.id << ": " << p.triangles.size() << " triangle lists for "
                             << p.polygons.size() << " polygons");
    bool object_started = false;
    for (std::size_t part = 0; part < p.polygons.size(); ++part) {
      const auto& polygon = p.polygons[part];
      const auto& triangles = p.triangles[part];
      if (polygon.size() < 3 || triangles.empty()) continue;
      for (const auto& t : triangles) {
        for (int k : t) {
          PLANESLAM_CHECK(k >= 0 && k < static_cast<int>(polygon.size()),
                          "plane " << p.id << ": triangle index " << k << " out of range");
        }
      }
      if (!object_started) mesh.objects.emplace_back(p.id, mesh.faces.size());
      object_started = true;
      const int base = static_cast<int>(mesh.vertices.size());
      for (const auto& v : polygon) {
        mesh.vertices.push_back(v.cast<float>());
        mesh.colors.push_back(p.color);
      }
      for (const auto& t : triangles) {
        mesh.faces.push_back({base + t[0], base + t[2], base + t[1]});
      }
    }
  }
  return mesh;
}

void WritePly(const std::string& path, const std::vector<Eigen::Vector3f>& vertices,
              const std::vector<Rgb8>& colors, const std::vector<std::array<int, 3>>& faces,
              PlyFormat format, const std::string& comment) {
  const bool binary = format == PlyFormat::kBinary;
  std::string out;
  out += "ply\n";
  out += binary ? "format binary_little_endian 1.0\n" : "format ascii 1.0\n";
  out += "comment " + comment + "\n";
  out += "element vertex " + std::to_string(vertices.size()) + "\n";
  out += "property float x\nproperty float y\nproperty float z\n";
  out += "property uchar red\nproperty uchar green\nproperty uchar blue\n";
  if (!faces.empty()) {
    out += "element face " + std::to_string(faces.size()) + "\n";
    out += "property list uchar int vertex_indices\n";
  }
  out += "end_header\n";
  if (binary) {
    out.reserve(out.size() + vertices.size() * 15 + faces.size() * 13);
    for (std::size_t i = 0; i < vertices.size(); ++i) {
      for (int k = 0; k < 3; ++k) PutLe(out, vertices[i][k]);
      for (int k = 0; k < 3; ++k) out.push_back(static_cast<char>(colors[i][k]));
    }
    for (const auto& f : faces) {
      out.push_back(static_cast<char>(3));
      for (int k = 0; k < 3; ++k) PutLe(out, static_cast<std::int32_t>(f[k]));
    }
  } else {
    char line[128];
    for (std::size_t i = 0; i < vertices.size(); ++i) {
      std::snprintf(line, sizeof(line), "%.9g %.9g %.9g %d %d %d\n", vertices[i].x(),
                    vertices[i].y(), vertices[i].z(), colors[i][0], colors[i][1], colors[i][2]);
      out += line;
    }
    for (const auto& f : faces) {
      std::snprintf(line, sizeof(line), "3 %d %d %d\n", f[0], f[1], f[2]);
      out += line;
    }
  }
  datasets::WriteFileAtomic(path, out);
}

}  // namespace

Rgb8 PlaneColor(int id) { return datasets::LabelColour(id); }

std::vector<MapPlaneRecord> MakeMapRecords(const PlaneMap& map, int min_observations,
                                           double min_area) {
  std::vector<MapPlaneRecord> records;
  for (const MapPlane& p : map.planes()) {
    if (static_cast<int>(p.observations.size()) < min_observations) continue;
    const MapPlaneOutline o = map.Outline(p);
    if (min_area > 0 && o.region.area < min_area) continue;
    MapPlaneRecord r;
    r.id = p.id;
    r.normal = p.normal;
    r.d = p.d;
    r.centroid = p.centroid;
    r.polygons = o.part_vertices;
    r.triangles = o.part_triangles;
    r.area = o.region.area;
    r.observed_area = o.observed_area;
    r.point_count = p.point_count();
    r.rms = std::sqrt(std::max(p.mse, 0.0));
    r.observations = static_cast<int>(p.observations.size());
    r.first_frame = p.first_keyframe;
    r.last_frame = p.last_keyframe;
    r.color = PlaneColor(p.id);
    records.push_back(std::move(r));
  }
  return records;
}

void WritePlaneMapPly(const std::string& path, const std::vector<MapPlaneRecord>& planes,
                      PlyFormat format) {
  const Mesh mesh = BuildMesh(planes);
  WritePly(path, mesh.vertices, mesh.colors, mesh.faces, format,
           "planeslam plane map: plane outlines, one colour per plane, world frame, metres");
}

void WritePlaneMapObj(const std::string& path, const std::vector<MapPlaneRecord>& planes) {
  const Mesh mesh = BuildMesh(planes);
  std::string out = "# planeslam plane map: plane outlines, world frame, metres\n";
  out += "# v x y z r g b (vertex colours in [0, 1]); one object per plane\n";
  char line[160];
  std::size_t v = 0;
  for (std::size_t o = 0; o < mesh.objects.size(); ++o) {
    const std::size_t face_begin = mesh.objects[o].second;
    const std::size_t face_end =
        o + 1 < mesh.objects.size() ? mesh.objects[o + 1].second : mesh.faces.size();
    out += "o plane_" + std::to_string(mesh.objects[o].first) + "\n";
    // This object's vertices: those referenced by its faces, which follow the previous object's.
    int max_index = -1;
    for (std::size_t f = face_begin; f < face_end; ++f) {
      for (int k : mesh.faces[f]) max_index = std::max(max_index, k);
    }
    for (; static_cast<int>(v) <= max_index; ++v) {
      const auto& p = mesh.vertices[v];
      const auto& c = mesh.colors[v];
      std::snprintf(line, sizeof(line), "v %.9g %.9g %.9g %.6g %.6g %.6g\n", p.x(), p.y(), p.z(),
                    c[0] / 255.0, c[1] / 255.0, c[2] / 255.0);
      out += line;
    }
    for (std::size_t f = face_begin; f < face_end; ++f) {
      const auto& t = mesh.faces[f];
      std::snprintf(line, sizeof(line), "f %d %d %d\n", t[0] + 1, t[1] + 1, t[2] + 1);
      out += line;
    }
  }
  datasets::WriteFileAtomic(path, out);
}

void WritePlaneMapJson(const std::string& path, const std::vector<MapPlaneRecord>& planes) {
  std::string out = "{\n  \"format\": \"planeslam-plane-map\",\n  \"version\": 2,\n";
  out += "  \"frame\": \"world\",\n  \"units\": \"m\",\n  \"planes\": [";
  for (std::size_t i = 0; i < planes.size(); ++i) {
    const MapPlaneRecord& p = planes[i];
    out += i == 0 ? "\n" : ",\n";
    out += "    {\"id\": " + std::to_string(p.id);
    out += ", \"normal\": " + Vec(p.normal);
    out += ", \"d\": " + Num(p.d);
    out += ", \"centroid\": " + Vec(p.centroid);
    out += ", \"area\": " + Num(p.area);
    out += ", \"observed_area\": " + Num(p.observed_area);
    out += ", \"point_count\": " + std::to_string(p.point_count);
    out += ", \"rms\": " + Num(p.rms);
    out += ", \"observations\": " + std::to_string(p.observations);
    out += ", \"first_frame\": " + std::to_string(p.first_frame);
    out += ", \"last_frame\": " + std::to_string(p.last_frame);
    out += ", \"color\": [" + std::to_string(p.color[0]) + ", " + std::to_string(p.color[1]) +
           ", " + std::to_string(p.color[2]) + "]";
    out += ",\n     \"polygons\": [";
    for (std::size_t part = 0; part < p.polygons.size(); ++part) {
      out += part == 0 ? "[" : ",\n       [";
      for (std::size_t k = 0; k < p.polygons[part].size(); ++k) {
        out += (k == 0 ? "" : ", ") + Vec(p.polygons[part][k]);
      }
      out += "]";
    }
    out += "]}";
  }
  out += planes.empty() ? "]\n}\n" : "\n  ]\n}\n";
  datasets::WriteFileAtomic(path, out);
}

void WriteColoredPointsPly(const std::string& path, const std::vector<Eigen::Vector3f>& points,
                           const std::vector<Rgb8>& colors, PlyFormat format) {
  PLANESLAM_CHECK(
      colors.empty() || colors.size() == points.size(),
      "colors (" << colors.size() << ") must be empty or match points (" << points.size() << ")");
  std::vector<Eigen::Vector3f> kept;
  std::vector<Rgb8> kept_colors;
  kept.reserve(points.size());
  kept_colors.reserve(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (!points[i].allFinite()) continue;
    kept.push_back(points[i]);
    kept_colors.push_back(colors.empty() ? Rgb8{255, 255, 255} : colors[i]);
  }
  WritePly(path, kept, kept_colors, {}, format, "planeslam coloured points, metres");
}

}  // namespace planeslam::mapping
