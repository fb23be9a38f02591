// Writes a rotating-LiDAR synthetic sequence in the KITTI odometry layout (see
// synthetic_writer.hpp), with per-return labels and planes.json in the first scan's frame.
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <sstream>

#include "planeslam/datasets/atomic_file.hpp"
#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/synthetic_lidar.hpp"
#include "planeslam/datasets/synthetic_writer.hpp"
#include "planeslam/datasets/trajectory_io.hpp"

namespace planeslam::datasets {

namespace {

namespace fs = std::filesystem;

void MakeDir(const std::string& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec || !fs::is_directory(dir)) throw IoError(dir, "cannot create folder: " + ec.message());
}

std::size_t FileSize(const std::string& path) {
  std::error_code ec;
  const auto size = fs::file_size(path, ec);
  return ec ? 0 : static_cast<std::size_t>(size);
}

/// The scene with every coordinate mapped by T (planes, polygons, disks, spheres, cylinders).
SyntheticScene TransformScene(const SyntheticScene& scene, const Pose& T) {
  SyntheticScene out = scene;
  const Eigen::Matrix3d R = T.linear();
  for (ScenePlane& p : out.planes) {
    p.normal = R * p.normal;
    p.d += p.normal.dot(T.translation());
    for (auto& poly : p.polygons)
      for (auto& v : poly) v = T * v;
    p.disk_center = T * p.disk_center;
  }
  for (SceneSphere& s : out.spheres) s.center = T * s.center;
  for (SceneCylinder& c : out.cylinders) {
    c.base = T * c.base;
    c.axis = R * c.axis;
  }
  return out;
}

std::string ScannerYaml(const RotatingLidar& lidar, double rate) {
  const LidarSimConfig& c = lidar.config();
  std::ostringstream os;
  os << "# planeslam synthetic rotating LiDAR: frame x forward, y left, z up. A scan is one\n"
     << "# clockwise turn; its stamp and pose are when it faces forward. In a .bin each laser's\n"
     << "# returns follow in turn, counter-clockwise from just left of ahead.\n"
     << "lasers: " << lidar.Height() << "\nfirings_per_turn: " << lidar.Width()
     << "\nscan_rate_hz: " << FormatRoundTrip(rate) << "\nelevations_deg: [";
  const auto& el = lidar.ElevationsDeg();
  for (std::size_t i = 0; i < el.size(); ++i) os << (i ? ", " : "") << FormatRoundTrip(el[i]);
  os << "]\nmin_range: " << FormatRoundTrip(c.min_range)
     << "\nmax_range: " << FormatRoundTrip(c.max_range)
     << "\nrange_sigma: " << FormatRoundTrip(c.noise ? c.range_sigma : 0.0)
     << "\nmotion_distortion: " << (c.motion_distortion ? "true" : "false") << "\n";
  return os.str();
}

std::string FrameName(std::size_t i) {
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%06zu", i);
  return buffer;
}

}  // namespace

std::vector<int> KittiColumnOrder(int columns) {
  // Column c looks at azimuth pi - 2 pi (c + 0.25) / columns: azimuth rises as c falls.
  const int last_left = static_cast<int>(std::ceil(0.5 * columns - 0.25)) - 1;
  std::vector<int> order;
  order.reserve(static_cast<std::size_t>(columns));
  for (int c = last_left; c >= 0; --c) order.push_back(c);
  for (int c = columns - 1; c > last_left; --c) order.push_back(c);
  return order;
}

SyntheticWriteSummary WriteSyntheticKitti(const SyntheticSequence& sequence,
                                          const std::string& folder,
                                          const std::function<bool(std::size_t)>& progress) {
  const auto* lidar = dynamic_cast<const RotatingLidar*>(&sequence.sensor());
  PLANESLAM_CHECK(lidar != nullptr, "KITTI layout needs the rotating LiDAR");
  const fs::path root(folder);
  MakeDir((root / "velodyne").string());
  MakeDir((root / "labels").string());
  SyntheticWriteSummary summary;
  auto track = [&summary](const std::string& path) {
    ++summary.files;
    summary.bytes += FileSize(path);
  };
  auto write_text = [&](const std::string& name, const std::string& text) {
    const std::string path = (root / name).string();
    WriteFileAtomic(path, text);
    track(path);
  };
  const std::vector<int> order = KittiColumnOrder(lidar->Width());
  const Pose T_first_world = sequence.GroundTruth(0)->inverse();
  Trajectory poses;
  const std::size_t n = sequence.Size();
  for (std::size_t i = 0; i < n; ++i) {
    const SyntheticFrame frame = sequence.Generate(i);
    const OrganizedCloud& cloud = frame.frame.cloud;
    std::string points, labels;
    points.reserve(cloud.points.size() * 16);
    labels.reserve(cloud.points.size() * 4);
    for (int r = 0; r < cloud.height; ++r) {
      for (int c : order) {
        const std::size_t k = static_cast<std::size_t>(r) * cloud.width + c;
        const Eigen::Vector3f& p = cloud.points[k];
        if (!OrganizedCloud::IsValid(p)) continue;
        const float record[4] = {p.x(), p.y(), p.z(), frame.intensity[k]};
        const std::uint32_t label = frame.labels.data[k];
        points.append(reinterpret_cast<const char*>(record), sizeof(record));
        labels.append(reinterpret_cast<const char*>(&label), sizeof(label));
      }
    }
    const std::string stem = FrameName(i);
    const std::string bin = (root / "velodyne" / (stem + ".bin")).string();
    WriteFileAtomic(bin, points);
    track(bin);
    const std::string label_path = (root / "labels" / (stem + ".label")).string();
    WriteFileAtomic(label_path, labels);
    track(label_path);
    poses.Add(frame.frame.timestamp, T_first_world * *frame.frame.T_world_sensor_gt);
    if (i == 0) {
      summary.preview_path = (root / "preview.png").string();
      WritePngRgb(summary.preview_path, MakeSyntheticPreview(frame, lidar->config().max_range));
      track(summary.preview_path);
    }
    ++summary.frames;
    if (progress && !progress(i + 1)) break;
  }
  const std::string poses_path = (root / "poses.txt").string();
  const std::string times_path = (root / "times.txt").string();
  WriteKittiTrajectory(poses_path, poses, times_path);
  track(poses_path);
  track(times_path);
  write_text("calib.txt", "Tr: 1 0 0 0 0 1 0 0 0 0 1 0\n");
  write_text("scanner.yaml", ScannerYaml(*lidar, sequence.config().trajectory.rate));
  write_text("planes.json",
             SyntheticPlanesJson(TransformScene(sequence.scene(), T_first_world),
                                 "first scan's scanner frame (the frame of poses.txt)"));
  return summary;
}

}  // namespace planeslam::datasets
