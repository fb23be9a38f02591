// Plane map writers: file contents read back byte by byte against the records written.
#include "planeslam/mapping/map_writers.hpp"

#include <gtest/gtest.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <set>
#include <sstream>

#include "planeslam/datasets/errors.hpp"
#include "test_support.hpp"

namespace planeslam::mapping {
namespace {

std::string ReadAll(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

/// A square on z = 1 (normal +z), a triangle on x = 2 (normal -x), a plane without an outline.
std::vector<MapPlaneRecord> Records() {
  MapPlaneRecord a;
  a.id = 1;
  a.normal = Eigen::Vector3d::UnitZ();
  a.d = 1.0;
  a.polygons = {{{0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}}};  // counter-clockwise about +z
  a.triangles = {{{{0, 1, 2}}, {{0, 2, 3}}}};
  a.area = 1.0;
  a.observations = 4;
  a.first_frame = 3;
  a.last_frame = 17;
  a.color = PlaneColor(1);
  MapPlaneRecord b;
  b.id = 5;
  b.normal = -Eigen::Vector3d::UnitX();
  b.d = -2.0;
  b.polygons = {{{2, 0, 0}, {2, 0, 1}, {2, 1, 0}}};  // counter-clockwise about -x
  b.triangles = {{{{0, 1, 2}}}};
  b.area = 0.5;
  b.color = PlaneColor(5);
  MapPlaneRecord c;
  c.id = 9;
  c.normal = Eigen::Vector3d(0.6, 0.0, 0.8);
  c.d = 0.1234567890123456789;
  return {a, b, c};
}

Eigen::Vector3d FaceNormal(const std::vector<Eigen::Vector3d>& v, int i, int j, int k) {
  return (v[j] - v[i]).cross(v[k] - v[i]);
}

TEST(MapWriters, BinaryPlyHoldsTheTrianglesWoundTowardsTheObservers) {
  const auto dir = test::ScratchDir();
  const auto records = Records();
  const auto path = (dir / "plane_map.ply").string();
  WritePlaneMapPly(path, records);
  const std::string bytes = ReadAll(path);
  const std::string end = "end_header\n";
  const std::size_t header_end = bytes.find(end);
  ASSERT_NE(header_end, std::string::npos);
  const std::string header = bytes.substr(0, header_end);
  EXPECT_NE(header.find("format binary_little_endian 1.0"), std::string::npos);
  EXPECT_NE(header.find("element vertex 7\n"), std::string::npos);
  EXPECT_NE(header.find("element face 3\n"), std::string::npos);
  EXPECT_NE(header.find("property list uchar int vertex_indices"), std::string::npos);
  const std::size_t body = header_end + end.size();
  ASSERT_EQ(bytes.size(), body + 7 * 15 + 3 * 13);

  std::vector<Eigen::Vector3d> vertices;
  const char* p = bytes.data() + body;
  for (int i = 0; i < 7; ++i, p += 15) {
    float xyz[3];
    std::memcpy(xyz, p, 12);  // the test hosts are little-endian
    vertices.emplace_back(xyz[0], xyz[1], xyz[2]);
    const int plane = i < 4 ? 0 : 1;
    for (int k = 0; k < 3; ++k) {
      EXPECT_EQ(static_cast<std::uint8_t>(p[12 + k]), records[plane].color[k]);
    }
  }
  EXPECT_EQ(vertices[2], Eigen::Vector3d(1, 1, 1));
  EXPECT_EQ(vertices[5], Eigen::Vector3d(2, 0, 1));
  for (int f = 0; f < 3; ++f, p += 13) {
    ASSERT_EQ(p[0], 3);
    std::int32_t idx[3];
    std::memcpy(idx, p + 1, 12);
    const int plane = f < 2 ? 0 : 1;
    for (int k = 0; k < 3; ++k) {
      EXPECT_GE(idx[k], plane == 0 ? 0 : 4);
      EXPECT_LT(idx[k], plane == 0 ? 4 : 7);
    }
    // Face normal opposite to the plane normal (the observers are on the negative side).
    const Eigen::Vector3d n = FaceNormal(vertices, idx[0], idx[1], idx[2]);
    EXPECT_LT(n.dot(records[plane].normal), -1e-6);
  }
  // The mesh area equals the outline areas.
  // (Checked through the ascii variant below; no temporary file is left behind.)
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    EXPECT_EQ(entry.path().filename(), "plane_map.ply");
  }
}

TEST(MapWriters, AsciiPlyMatchesTheBinaryOne) {
  const auto dir = test::ScratchDir();
  const auto path = (dir / "plane_map.ply").string();
  WritePlaneMapPly(path, Records(), PlyFormat::kAscii);
  std::istringstream in(ReadAll(path));
  std::string line;
  int vertices = -1, faces = -1;
  while (std::getline(in, line) && line != "end_header") {
    std::sscanf(line.c_str(), "element vertex %d", &vertices);
    std::sscanf(line.c_str(), "element face %d", &faces);
  }
  ASSERT_EQ(vertices, 7);
  ASSERT_EQ(faces, 3);
  std::vector<Eigen::Vector3d> v;
  for (int i = 0; i < vertices; ++i) {
    double x, y, z;
    int r, g, b;
    in >> x >> y >> z >> r >> g >> b;
    v.emplace_back(x, y, z);
  }
  double area = 0;
  for (int f = 0; f < faces; ++f) {
    int n, i, j, k;
    in >> n >> i >> j >> k;
    ASSERT_EQ(n, 3);
    area += 0.5 * FaceNormal(v, i, j, k).norm();
  }
  EXPECT_TRUE(static_cast<bool>(in));
  EXPECT_NEAR(area, 1.5, 1e-12);
}

TEST(MapWriters, ObjHasOneObjectPerPlaneAndOneBasedFaces) {
  const auto dir = test::ScratchDir();
  const auto path = (dir / "plane_map.obj").string();
  const auto records = Records();
  WritePlaneMapObj(path, records);
  std::istringstream in(ReadAll(path));
  std::string line;
  std::vector<Eigen::Vector3d> v;
  std::vector<std::string> objects;
  std::vector<std::array<int, 3>> faces;
  while (std::getline(in, line)) {
    std::istringstream ls(line);
    std::string tag;
    ls >> tag;
    if (tag == "v") {
      double x, y, z, r, g, b;
      ls >> x >> y >> z >> r >> g >> b;
      ASSERT_TRUE(static_cast<bool>(ls)) << line;
      EXPECT_GE(r, 0.0);
      EXPECT_LE(r, 1.0);
      v.emplace_back(x, y, z);
    } else if (tag == "o") {
      std::string name;
      ls >> name;
      objects.push_back(name);
    } else if (tag == "f") {
      std::array<int, 3> f;
      ls >> f[0] >> f[1] >> f[2];
      faces.push_back(f);
    }
  }
  EXPECT_EQ(objects, (std::vector<std::string>{"plane_1", "plane_5"}));
  ASSERT_EQ(v.size(), 7u);
  ASSERT_EQ(faces.size(), 3u);
  for (std::size_t f = 0; f < faces.size(); ++f) {
    for (int k : faces[f]) {
      EXPECT_GE(k, 1);
      EXPECT_LE(k, 7);
    }
    const Eigen::Vector3d n = FaceNormal(v, faces[f][0] - 1, faces[f][1] - 1, faces[f][2] - 1);
    EXPECT_LT(n.dot(records[f < 2 ? 0 : 1].normal), -1e-6);
  }
}

TEST(MapWriters, APlaneOfTwoPartsIsOneObjectWithBothParts) {
  // A floor seen in two pieces 3 m apart: one plane, one colour, one OBJ object, two JSON polygons.
  MapPlaneRecord floor;
  floor.id = 4;
  floor.polygons = {{{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}},
                    {{4, 0, 0}, {4.5, 0, 0}, {4.5, 1, 0}}};
  floor.triangles = {{{{0, 1, 2}}, {{0, 2, 3}}}, {{{0, 1, 2}}}};
  floor.area = 1.25;
  floor.color = PlaneColor(4);
  const auto dir = test::ScratchDir();
  WritePlaneMapPly((dir / "floor.ply").string(), {floor}, PlyFormat::kAscii);
  const std::string ply = ReadAll(dir / "floor.ply");
  EXPECT_NE(ply.find("element vertex 7\n"), std::string::npos);
  EXPECT_NE(ply.find("element face 3\n"), std::string::npos);
  // The second part's face indexes its own vertices, after the first part's four.
  EXPECT_NE(ply.find("3 4 6 5\n"), std::string::npos);

  WritePlaneMapObj((dir / "floor.obj").string(), {floor});
  const std::string obj = ReadAll(dir / "floor.obj");
  EXPECT_EQ(obj.find("o plane_4"), obj.rfind("o plane_"));  // one object
  EXPECT_NE(obj.find("f 5 7 6\n"), std::string::npos);

  WritePlaneMapJson((dir / "floor.json").string(), {floor});
  const std::string json = ReadAll(dir / "floor.json");
  EXPECT_NE(json.find("\"polygons\": [[[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]],\n"
                      "       [[4, 0, 0], [4.5, 0, 0], [4.5, 1, 0]]]"),
            std::string::npos)
      << json;

  MapPlaneRecord broken = floor;
  broken.triangles.pop_back();  // one triangle list for two polygons
  EXPECT_THROW(WritePlaneMapPly((dir / "broken.ply").string(), {broken}), CheckError);
}

TEST(MapWriters, JsonListsEveryPlaneWithRoundTrippingNumbers) {
  const auto dir = test::ScratchDir();
  const auto path = (dir / "plane_map.json").string();
  WritePlaneMapJson(path, Records());
  const std::string text = ReadAll(path);
  EXPECT_NE(text.find("\"format\": \"planeslam-plane-map\""), std::string::npos);
  EXPECT_NE(text.find("\"id\": 9"), std::string::npos);
  EXPECT_NE(text.find("\"version\": 2"), std::string::npos);
  EXPECT_NE(text.find("\"polygons\": []"), std::string::npos);  // no outline: still listed
  EXPECT_NE(text.find("\"first_frame\": 3, \"last_frame\": 17"), std::string::npos);
  const std::size_t at = text.find("\"d\": ", text.find("\"id\": 9"));
  ASSERT_NE(at, std::string::npos);
  EXPECT_EQ(std::strtod(text.c_str() + at + 5, nullptr), 0.1234567890123456789);
  // Balanced brackets (a cheap structural check; the PCL suite parses it with nlohmann-json).
  int depth = 0;
  for (char ch : text) {
    depth += (ch == '[' || ch == '{') - (ch == ']' || ch == '}');
    ASSERT_GE(depth, 0);
  }
  EXPECT_EQ(depth, 0);
  WritePlaneMapJson(path, {});
  EXPECT_NE(ReadAll(path).find("\"planes\": []"), std::string::npos);
}

TEST(MapWriters, ColoredPointsSkipInvalidPoints) {
  const auto dir = test::ScratchDir();
  const auto path = (dir / "points.ply").string();
  const float nan = std::numeric_limits<float>::quiet_NaN();
  WriteColoredPointsPly(path, {{1, 2, 3}, {nan, nan, nan}, {4, 5, 6}},
                        {{{1, 2, 3}}, {{0, 0, 0}}, {{7, 8, 9}}}, PlyFormat::kAscii);
  const std::string text = ReadAll(path);
  EXPECT_NE(text.find("element vertex 2\n"), std::string::npos);
  EXPECT_EQ(text.find("element face"), std::string::npos);
  EXPECT_NE(text.find("end_header\n1 2 3 1 2 3\n4 5 6 7 8 9\n"), std::string::npos);
  EXPECT_THROW(WriteColoredPointsPly(path, {{1, 2, 3}}, {{{1, 2, 3}}, {{1, 2, 3}}}), CheckError);
}

TEST(MapWriters, UnwritablePathThrowsIoErrorNamingIt) {
  const auto dir = test::ScratchDir();
  const std::string path = (dir / "missing" / "plane_map.ply").string();
  try {
    WritePlaneMapPly(path, Records());
    FAIL() << "no exception";
  } catch (const IoError& e) {
    EXPECT_EQ(e.file(), path);
  }
  EXPECT_THROW(WritePlaneMapObj(path, Records()), IoError);
  EXPECT_THROW(WritePlaneMapJson(path, Records()), IoError);
}

TEST(MapWriters, SameRecordsGiveIdenticalFiles) {
  const auto dir = test::ScratchDir();
  for (const char* name : {"a", "b"}) {
    const std::string base = (dir / name).string();
    WritePlaneMapPly(base + ".ply", Records());
    WritePlaneMapObj(base + ".obj", Records());
    WritePlaneMapJson(base + ".json", Records());
  }
  for (const char* ext : {".ply", ".obj", ".json"}) {
    EXPECT_EQ(ReadAll(dir / (std::string("a") + ext)), ReadAll(dir / (std::string("b") + ext)));
  }
}

TEST(MapWriters, PlaneColorsAreDeterministicAndDistinct) {
  std::set<Rgb8> seen;
  for (int id = 1; id <= 30; ++id) {
    EXPECT_EQ(PlaneColor(id), PlaneColor(id));
    seen.insert(PlaneColor(id));
  }
  EXPECT_EQ(seen.size(), 30u);
  // Neighbouring ids are far apart in colour.
  for (int id = 1; id < 30; ++id) {
    const Rgb8 a = PlaneColor(id), b = PlaneColor(id + 1);
    int diff = 0;
    for (int k = 0; k < 3; ++k) diff += std::abs(a[k] - b[k]);
    EXPECT_GT(diff, 60) << id;
  }
}

TEST(MapWriters, RecordsFromAPlaneMapCarryOutlinesOnTheirPlanes) {
  // One 2 x 1 m patch at z = 3 seen from the origin.
  std::vector<Eigen::Vector3f> pts;
  detection::Plane plane;
  plane.id = 1;
  for (int i = 0; i < 100; ++i) {
    for (int j = 0; j < 50; ++j) {
      pts.emplace_back(-1.0f + 0.02f * i + 0.01f, -0.5f + 0.02f * j + 0.01f, 3.0f);
      plane.moments.Add(pts.back());
    }
  }
  const auto fit = plane.moments.Fit();
  plane.normal = fit.normal;
  plane.d = fit.d;
  PlaneMap map;
  map.AddObservations(7, Pose::Identity(), {plane}, {pts});
  const auto records = MakeMapRecords(map);
  ASSERT_EQ(records.size(), 1u);
  const MapPlaneRecord& r = records[0];
  EXPECT_EQ(r.id, 1);
  EXPECT_EQ(r.first_frame, 7);
  EXPECT_EQ(r.observations, 1);
  EXPECT_EQ(r.point_count, 5000);
  EXPECT_NEAR(r.d, 3.0, 1e-9);
  EXPECT_NEAR(r.area, 2.0, 0.15 * 2.0);
  ASSERT_EQ(r.polygons.size(), 1u);
  ASSERT_GE(r.polygons[0].size(), 4u);
  ASSERT_EQ(r.triangles.size(), 1u);
  EXPECT_EQ(r.triangles[0].size(), r.polygons[0].size() - 2);
  for (const auto& v : r.polygons[0]) EXPECT_NEAR(v.z(), 3.0, 1e-9);
  EXPECT_EQ(r.color, PlaneColor(1));
  EXPECT_TRUE(MakeMapRecords(map, 2).empty());       // seen once only
  EXPECT_TRUE(MakeMapRecords(map, 1, 2.5).empty());  // smaller than 2.5 m^2
  EXPECT_EQ(MakeMapRecords(map, 1, 1.5).size(), 1u);
}

}  // namespace
}  // namespace planeslam::mapping
