// Reads a 16-bit depth PNG, back-projects it with the given pinhole intrinsics and prints the
// planes that grid-based region growing (GBRG) finds in it.
//   detect_planes DEPTH.png FX FY CX CY [DEPTH_SCALE]   (DEPTH_SCALE: PNG units per metre)
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>

#include "planeslam/datasets/depth_image.hpp"
#include "planeslam/datasets/image_io.hpp"
#include "planeslam/detection/grid_region_growing.hpp"

namespace ds = planeslam::datasets;
namespace det = planeslam::detection;

int main(int argc, char** argv) {
  if (argc != 6 && argc != 7) {
    std::fprintf(stderr, "usage: %s DEPTH.png FX FY CX CY [DEPTH_SCALE]\n", argv[0]);
    return 2;
  }
  try {
    const ds::Image16 depth = ds::ReadPng16(argv[1]);
    ds::PinholeIntrinsics intrinsics;
    intrinsics.width = depth.width;
    intrinsics.height = depth.height;
    intrinsics.fx = std::atof(argv[2]);
    intrinsics.fy = std::atof(argv[3]);
    intrinsics.cx = std::atof(argv[4]);
    intrinsics.cy = std::atof(argv[5]);
    const double depth_scale = argc == 7 ? std::atof(argv[6]) : 5000.0;
    const ds::OrganizedCloud cloud = ds::DepthToCloud(depth, intrinsics, depth_scale);

    // The defaults give the planes of `planeslam detect -m grid --intrinsics FILE` (3x3 grids).
    const det::GridRegionGrowing detector(det::DetectionParams{}, det::GridParams{});
    const det::Segmentation segmentation = detector.Detect(cloud);

    std::printf("%s: %zu planes in %dx%d\n", detector.Name().c_str(),
                segmentation.planes.size(), segmentation.width, segmentation.height);
    for (const det::Plane& plane : segmentation.planes) {
      std::printf("plane %d: n = (%.4f %.4f %.4f) d = %.4f m, %lld points, rms %.2f mm\n",
                  plane.id, plane.normal.x(), plane.normal.y(), plane.normal.z(), plane.d,
                  static_cast<long long>(plane.point_count), 1000.0 * std::sqrt(plane.mse));
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 1;
  }
  return 0;
}
