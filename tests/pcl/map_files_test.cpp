// The plane map files open in PCL's own readers (PLY: PCL's parser and VTK's; OBJ: PCL's parser)
// and the JSON in nlohmann-json, with the content that was written.
#include <gtest/gtest.h>
#include <pcl/PolygonMesh.h>
#include <pcl/common/io.h>
#include <pcl/conversions.h>
#include <pcl/io/obj_io.h>
#include <pcl/io/ply_io.h>
#include <pcl/io/vtk_lib_io.h>
#include <pcl/point_types.h>

#include <fstream>
#include <nlohmann/json.hpp>

#include "planeslam/mapping/map_writers.hpp"
#include "test_support.hpp"

namespace planeslam::mapping {
namespace {

/// A map of two planes seen from the origin: at z = 3 a 2 x 1 m patch and a 0.6 x 1 m patch 2 m
/// beside it (one plane, two outline parts), and a 1 x 1 m patch at x = 1.5 (all from grid
/// points), through PlaneMap and MakeMapRecords.
std::vector<MapPlaneRecord> MapRecords() {
  std::vector<detection::Plane> planes(2);
  std::vector<std::vector<Eigen::Vector3f>> points(2);
  for (int i = 0; i < 100; ++i) {
    for (int j = 0; j < 50; ++j) points[0].emplace_back(-1.0f + 0.02f * i, -0.5f + 0.02f * j, 3.0f);
  }
  for (int i = 0; i < 30; ++i) {
    for (int j = 0; j < 50; ++j) points[0].emplace_back(3.0f + 0.02f * i, -0.5f + 0.02f * j, 3.0f);
  }
  for (int i = 0; i < 50; ++i) {
    for (int j = 0; j < 50; ++j) points[1].emplace_back(1.5f, -0.5f + 0.02f * i, 1.0f + 0.02f * j);
  }
  for (int k = 0; k < 2; ++k) {
    planes[k].id = k + 1;
    for (const auto& p : points[k]) planes[k].moments.Add(p);
    const auto fit = planes[k].moments.Fit();
    planes[k].normal = fit.normal;
    planes[k].d = fit.d;
  }
  PlaneMap map;
  map.AddObservations(0, Pose::Identity(), planes, points);
  auto records = MakeMapRecords(map);
  EXPECT_EQ(records.size(), 2u);
  EXPECT_EQ(records[0].polygons.size(), 2u);
  return records;
}

std::size_t FaceCount(const std::vector<MapPlaneRecord>& records) {
  std::size_t n = 0;
  for (const auto& r : records) {
    for (const auto& part : r.triangles) n += part.size();
  }
  return n;
}

std::size_t VertexCount(const std::vector<MapPlaneRecord>& records) {
  std::size_t n = 0;
  for (const auto& r : records) {
    for (const auto& part : r.polygons) n += part.size();
  }
  return n;
}

/// Checks a mesh read back: sizes, vertex positions and colours, in writing order.
void ExpectMesh(const pcl::PolygonMesh& mesh, const std::vector<MapPlaneRecord>& records,
                bool check_colors) {
  ASSERT_EQ(mesh.polygons.size(), FaceCount(records));
  pcl::PointCloud<pcl::PointXYZRGB> cloud;
  if (check_colors) {
    pcl::fromPCLPointCloud2(mesh.cloud, cloud);
  } else {  // PCL's OBJ reader drops vertex colours: read positions only (no "missing rgb" notice)
    pcl::PointCloud<pcl::PointXYZ> xyz;
    pcl::fromPCLPointCloud2(mesh.cloud, xyz);
    pcl::copyPointCloud(xyz, cloud);
  }
  ASSERT_EQ(cloud.size(), VertexCount(records));
  std::size_t v = 0;
  for (const auto& r : records) {
    for (const auto& part : r.polygons) {
      for (const auto& p : part) {
        EXPECT_NEAR(cloud[v].x, p.x(), 1e-5);
        EXPECT_NEAR(cloud[v].y, p.y(), 1e-5);
        EXPECT_NEAR(cloud[v].z, p.z(), 1e-5);
        if (check_colors) {
          EXPECT_EQ(cloud[v].r, r.color[0]);
          EXPECT_EQ(cloud[v].g, r.color[1]);
          EXPECT_EQ(cloud[v].b, r.color[2]);
        }
        ++v;
      }
    }
  }
  for (const auto& poly : mesh.polygons) {
    ASSERT_EQ(poly.vertices.size(), 3u);
    for (auto idx : poly.vertices) EXPECT_LT(idx, cloud.size());
  }
}

TEST(MapFiles, PlyOpensInPclAndVtkReaders) {
  const auto dir = test::ScratchDir();
  const auto records = MapRecords();
  ASSERT_GT(FaceCount(records), 0u);
  for (const PlyFormat format : {PlyFormat::kBinary, PlyFormat::kAscii}) {
    const std::string path = (dir / "plane_map.ply").string();
    WritePlaneMapPly(path, records, format);
    pcl::PolygonMesh mesh;
    ASSERT_EQ(pcl::io::loadPLYFile(path, mesh), 0);
    ExpectMesh(mesh, records, /*check_colors=*/true);
    pcl::PolygonMesh vtk_mesh;
    ASSERT_GT(pcl::io::loadPolygonFilePLY(path, vtk_mesh), 0);
    EXPECT_EQ(vtk_mesh.polygons.size(), FaceCount(records));
  }
}

TEST(MapFiles, ObjOpensInPclReader) {
  const auto dir = test::ScratchDir();
  const auto records = MapRecords();
  const std::string path = (dir / "plane_map.obj").string();
  WritePlaneMapObj(path, records);
  pcl::PolygonMesh mesh;
  ASSERT_EQ(pcl::io::loadOBJFile(path, mesh), 0);
  ExpectMesh(mesh, records, /*check_colors=*/false);
}

TEST(MapFiles, JsonParsesWithTheWrittenValues) {
  const auto dir = test::ScratchDir();
  const auto records = MapRecords();
  const std::string path = (dir / "plane_map.json").string();
  WritePlaneMapJson(path, records);
  std::ifstream in(path);
  const nlohmann::json j = nlohmann::json::parse(in);
  EXPECT_EQ(j.at("format"), "planeslam-plane-map");
  ASSERT_EQ(j.at("planes").size(), records.size());
  for (std::size_t i = 0; i < records.size(); ++i) {
    const auto& p = j.at("planes")[i];
    EXPECT_EQ(p.at("id").get<int>(), records[i].id);
    EXPECT_EQ(p.at("d").get<double>(), records[i].d);  // exact round trip
    EXPECT_EQ(p.at("normal")[2].get<double>(), records[i].normal.z());
    EXPECT_EQ(p.at("area").get<double>(), records[i].area);
    ASSERT_EQ(p.at("polygons").size(), records[i].polygons.size());
    ASSERT_EQ(p.at("polygons")[0].size(), records[i].polygons[0].size());
    EXPECT_EQ(p.at("polygons")[0][0][1].get<double>(), records[i].polygons[0][0].y());
    EXPECT_EQ(p.at("polygons").back().size(), records[i].polygons.back().size());
    EXPECT_EQ(p.at("observations").get<int>(), 1);
  }
}

TEST(MapFiles, ColoredPointsOpenAsPointXYZRGB) {
  const auto dir = test::ScratchDir();
  const std::string path = (dir / "points.ply").string();
  std::vector<Eigen::Vector3f> pts = {{1, 2, 3}, {-4, 5.5f, 6}};
  WriteColoredPointsPly(path, pts, {{{10, 20, 30}}, {{200, 100, 0}}});
  pcl::PointCloud<pcl::PointXYZRGB> cloud;
  ASSERT_EQ(pcl::io::loadPLYFile(path, cloud), 0);
  ASSERT_EQ(cloud.size(), 2u);
  EXPECT_FLOAT_EQ(cloud[1].y, 5.5f);
  EXPECT_EQ(cloud[1].r, 200);
  EXPECT_EQ(cloud[0].b, 30);
}

}  // namespace
}  // namespace planeslam::mapping
