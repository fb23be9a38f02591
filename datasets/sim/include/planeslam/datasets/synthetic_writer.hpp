#pragma once
/// Writes a SyntheticSequence to disk with its ground truth.
///
/// Pinhole sensor, TUM RGB-D layout (readable by OpenTumSequence / OpenSequence):
///   depth/<stamp>.png    16-bit, value = depth [m] * 5000, 0 = no measurement
///   depth.txt            `stamp depth/<stamp>.png` per frame
///   intrinsics.yaml      width height fx fy cx cy depth_scale
/// Spherical scanner, organized PCD folder (readable by OpenPcdFolder with pcd_model spherical):
///   <stamp>.pcd          binary organized cloud, sensor frame (x forward, y left, z up), NaN = none
///   scanner.yaml         the scanner geometry (resolution, field of view, ranges)
/// Rotating LiDAR, KITTI odometry layout (readable by OpenKittiFolder / OpenSequence):
///   velodyne/NNNNNN.bin  float32 x y z reflectance per return, scanner frame at its firing; each
///                        laser's returns in turn, counter-clockwise from just left of ahead
///   labels/NNNNNN.label  uint32 plane id per return, in the .bin's order (0 = no plane)
///   times.txt            stamp of each scan [s], one a line
///   poses.txt            scanner pose of each scan in the first scan's frame, 12 numbers a line
///                        (3x4 [R|t] row-major), as KITTI's ground truth for the Velodyne
///   calib.txt            `Tr:` identity: the poses are the scanner's own
///   scanner.yaml         laser elevations, firings per turn, range limits, noise, distortion
///   planes.json          as below, in the first scan's frame (the frame of poses.txt)
///   preview.png          frame 0 as a range image (row per laser) and its labels
/// Pinhole and spherical:
///   labels/<stamp>.png   16-bit plane id per pixel (0 = no plane), same grid as the frame
///   groundtruth.txt      exact T_world_sensor, `stamp tx ty tz qx qy qz qw`, round-trip digits
///   planes.json          every plane: id, name, world n and d (n.p = d), polygons, area; spheres,
///                        cylinders
///   preview.png          frame 0: depth (grey) and labels (colour) side by side
/// Stamps are i / rate rounded to microseconds, written with 6 decimals. Every file goes through
/// the atomic writers; the same sequence config gives byte-identical files.
#include <cstddef>
#include <functional>
#include <string>
#include <vector>

#include "planeslam/datasets/image_io.hpp"
#include "planeslam/datasets/synthetic_sequence.hpp"

namespace planeslam::datasets {

/// What was written.
struct SyntheticWriteSummary {
  std::size_t frames = 0;
  std::size_t files = 0;
  std::size_t bytes = 0;         ///< total size of the files written
  std::string preview_path;      ///< empty when no frame was written
};

/// Writes frames [0, frames) (frames = 0: all) into `folder` (created by the caller). `progress`
/// is called after each frame with the number done; when it returns false, writing stops after
/// that frame and the index files list the frames written so far. Throws IoError naming the file.
SyntheticWriteSummary WriteSyntheticSequence(
    const SyntheticSequence& sequence, const std::string& folder,
    const std::function<bool(std::size_t done)>& progress = {});

/// Depth (grey: near bright, far dark over the frame's range up to max_range, black = none) and
/// labels (a colour per plane id, grey for curved surfaces, black = none) side by side,
/// 2 * width x height.
ImageRgb8 MakeSyntheticPreview(const SyntheticFrame& frame, double max_range);


/// planes.json text for a scene; `frame` describes the frame of its coordinates (empty: the
/// scene's world frame).
std::string SyntheticPlanesJson(const SyntheticScene& scene, const std::string& frame = "");

/// The rotating-LiDAR part of WriteSyntheticSequence (KITTI odometry layout, see above).
SyntheticWriteSummary WriteSyntheticKitti(const SyntheticSequence& sequence,
                                          const std::string& folder,
                                          const std::function<bool(std::size_t done)>& progress);

/// Order in which a .bin lists the columns of one laser: counter-clockwise from the first
/// column left of straight ahead, as KITTI stores a sweep.
std::vector<int> KittiColumnOrder(int columns);

/// File name stem of a stamp: "%.6f".
std::string StampName(double stamp);

}  // namespace planeslam::datasets
