// Writes synthetic sequences in the TUM layout (pinhole) or as an organized PCD folder (spherical),
// with labels, exact ground truth and planes.json.
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <sstream>

#include "planeslam/datasets/atomic_file.hpp"
#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/pcd_io.hpp"
#include "planeslam/datasets/synthetic_writer.hpp"
#include "planeslam/datasets/trajectory_io.hpp"

namespace planeslam::datasets {

namespace {

namespace fs = std::filesystem;
constexpr double kDepthScale = 5000.0;  // TUM: PNG value / 5000 = metres

nlohmann::json Vec(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }

std::size_t FileSize(const std::string& path) {
  std::error_code ec;
  const auto size = fs::file_size(path, ec);
  return ec ? 0 : static_cast<std::size_t>(size);
}

void MakeDir(const std::string& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec || !fs::is_directory(dir)) throw IoError(dir, "cannot create folder: " + ec.message());
}

/// Depth PNG of a pinhole frame: round(z * 5000); 0 where invalid or beyond 16 bits (13.1 m).
Image16 DepthImage(const OrganizedCloud& cloud) {
  Image16 image(cloud.width, cloud.height);
  for (std::size_t i = 0; i < cloud.points.size(); ++i) {
    const Eigen::Vector3f& p = cloud.points[i];
    if (!OrganizedCloud::IsValid(p)) continue;
    const double v = std::round(p.z() * kDepthScale);
    if (v >= 1.0 && v <= 65535.0) image.data[i] = static_cast<std::uint16_t>(v);
  }
  return image;
}

std::string IntrinsicsYaml(const PinholeIntrinsics& K) {
  std::ostringstream os;
  os << "# planeslam synthetic depth camera (pinhole, optical frame x right, y down, z forward).\n"
     << "# Depth PNG: 16-bit, value / depth_scale = metres; 0 = no measurement.\n"
     << "width: " << K.width << "\nheight: " << K.height << "\nfx: " << FormatRoundTrip(K.fx)
     << "\nfy: " << FormatRoundTrip(K.fy) << "\ncx: " << FormatRoundTrip(K.cx)
     << "\ncy: " << FormatRoundTrip(K.cy) << "\ndepth_scale: " << FormatRoundTrip(kDepthScale)
     << "\n";
  return os.str();
}

std::string ScannerYaml(const SphericalSimConfig& c) {
  std::ostringstream os;
  os << "# planeslam synthetic spherical scanner: frame x forward, y left, z up. Rows are\n"
     << "# elevation (row r: elevation_max_deg - r * elevation_resolution_deg), columns azimuth\n"
     << "# (column c: azimuth_fov_deg / 2 - (c + 0.5) * azimuth_resolution_deg).\n"
     << "width: " << c.Width() << "\nheight: " << c.Height()
     << "\nazimuth_fov_deg: " << FormatRoundTrip(c.azimuth_fov_deg)
     << "\nazimuth_resolution_deg: " << FormatRoundTrip(c.azimuth_resolution_deg)
     << "\nelevation_min_deg: " << FormatRoundTrip(c.elevation_min_deg)
     << "\nelevation_max_deg: " << FormatRoundTrip(c.elevation_max_deg)
     << "\nelevation_resolution_deg: " << FormatRoundTrip(c.elevation_resolution_deg)
     << "\nmin_range: " << FormatRoundTrip(c.min_range)
     << "\nmax_range: " << FormatRoundTrip(c.max_range)
     << "\nrange_sigma: " << FormatRoundTrip(c.noise ? c.range_sigma : 0.0) << "\n";
  return os.str();
}

}  // namespace

std::string StampName(double stamp) {
  char buffer[64];
  std::snprintf(buffer, sizeof(buffer), "%.6f", stamp);
  return buffer;
}

ImageRgb8 MakeSyntheticPreview(const SyntheticFrame& frame, double max_range) {
  const OrganizedCloud& cloud = frame.frame.cloud;
  const int w = cloud.width, h = cloud.height;
  ImageRgb8 image(2 * w, h);
  const bool pinhole = cloud.model == SensorModel::kPinhole;
  // Grey scale over the frame's own range of values (up to max_range) for contrast.
  double lo = max_range, hi = 0.0;
  for (const auto& p : cloud.points) {
    if (!OrganizedCloud::IsValid(p)) continue;
    const double range = pinhole ? p.z() : p.norm();
    lo = std::min(lo, range);
    hi = std::max(hi, std::min(range, max_range));
  }
  const double span = std::max(hi - lo, 1e-6);
  for (int r = 0; r < h; ++r) {
    for (int c = 0; c < w; ++c) {
      const std::size_t i = static_cast<std::size_t>(r) * w + c;
      const Eigen::Vector3f& p = cloud.points[i];
      std::uint8_t* grey = &image.data[3 * (static_cast<std::size_t>(r) * 2 * w + c)];
      std::uint8_t* colour = grey + 3 * w;
      if (!OrganizedCloud::IsValid(p)) continue;  // black
      const double range = pinhole ? p.z() : p.norm();
      const double x = std::clamp((range - lo) / span, 0.0, 1.0);
      const auto g = static_cast<std::uint8_t>(std::lround(255.0 - 215.0 * x));
      grey[0] = grey[1] = grey[2] = g;
      const auto label_rgb = LabelColour(frame.labels.data[i]);
      std::copy(label_rgb.begin(), label_rgb.end(), colour);
    }
  }
  return image;
}

std::string SyntheticPlanesJson(const SyntheticScene& scene, const std::string& frame) {
  nlohmann::json planes = nlohmann::json::array();
  for (const ScenePlane& p : scene.planes) {
    nlohmann::json polys = nlohmann::json::array();
    for (const auto& poly : p.polygons) {
      nlohmann::json corners = nlohmann::json::array();
      for (const auto& c : poly) corners.push_back(Vec(c));
      polys.push_back(corners);
    }
    nlohmann::json plane = {{"id", p.id},         {"name", p.name}, {"normal", Vec(p.normal)},
                            {"d", p.d},           {"area", p.Area()}, {"polygons", polys}};
    if (p.is_disk) {
      plane["disk"] = {{"center", Vec(p.disk_center)}, {"radius", p.disk_radius}};
    }
    planes.push_back(plane);
  }
  nlohmann::json spheres = nlohmann::json::array();
  for (const auto& s : scene.spheres) spheres.push_back({{"center", Vec(s.center)}, {"radius", s.radius}});
  nlohmann::json cylinders = nlohmann::json::array();
  for (const auto& c : scene.cylinders) {
    cylinders.push_back({{"base", Vec(c.base)},       {"axis", Vec(c.axis)},
                         {"length", c.length},        {"radius", c.radius},
                         {"base_cap_id", c.base_cap_id}, {"top_cap_id", c.top_cap_id}});
  }
  nlohmann::json doc = {
      {"scene", scene.name},
      {"frame", (frame.empty() ? std::string("world, z up") : frame) +
                    ", metres; plane points p satisfy normal . p = d; polygons are convex "
                    "pieces, corners counter-clockwise seen from the normal side; a disk's "
                    "polygon is a 32-gon outline"},
      {"planes", planes},
      {"spheres", spheres},
      {"cylinders", cylinders}};
  return doc.dump(1) + "\n";
}

SyntheticWriteSummary WriteSyntheticSequence(const SyntheticSequence& sequence,
                                             const std::string& folder,
                                             const std::function<bool(std::size_t)>& progress) {
  if (sequence.config().sensor == "lidar") return WriteSyntheticKitti(sequence, folder, progress);
  const bool pinhole = sequence.sensor().Model() == SensorModel::kPinhole;
  const fs::path root(folder);
  MakeDir((root / "labels").string());
  if (pinhole) MakeDir((root / "depth").string());
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

  std::ostringstream list;
  list << "# depth maps\n# planeslam synthetic " << SceneName(sequence.config().scene)
       << " seed " << sequence.config().seed << "\n# timestamp filename\n";
  Trajectory gt;
  const std::size_t n = sequence.Size();
  for (std::size_t i = 0; i < n; ++i) {
    const SyntheticFrame frame = sequence.Generate(i);
    const std::string stem = StampName(frame.frame.timestamp);
    if (pinhole) {
      const std::string rel = "depth/" + stem + ".png";
      WritePng16((root / rel).string(), DepthImage(frame.frame.cloud));
      track((root / rel).string());
      list << stem << " " << rel << "\n";
    } else {
      const std::string path = (root / (stem + ".pcd")).string();
      WritePcd(path, frame.frame.cloud);
      track(path);
    }
    const std::string label_path = (root / "labels" / (stem + ".png")).string();
    WritePng16(label_path, frame.labels);
    track(label_path);
    gt.Add(frame.frame.timestamp, *frame.frame.T_world_sensor_gt);
    if (i == 0) {
      const double max_range =
          pinhole ? sequence.config().pinhole.max_depth : sequence.config().spherical.max_range;
      summary.preview_path = (root / "preview.png").string();
      WritePngRgb(summary.preview_path, MakeSyntheticPreview(frame, max_range));
      track(summary.preview_path);
    }
    ++summary.frames;
    if (progress && !progress(i + 1)) break;
  }
  if (pinhole) {
    write_text("depth.txt", list.str());
    write_text("intrinsics.yaml", IntrinsicsYaml(sequence.config().pinhole.intrinsics));
  } else {
    write_text("scanner.yaml", ScannerYaml(sequence.config().spherical));
  }
  const std::string gt_path = (root / "groundtruth.txt").string();
  WriteTumTrajectory(gt_path, gt);
  track(gt_path);
  write_text("planes.json", SyntheticPlanesJson(sequence.scene()));
  return summary;
}

}  // namespace planeslam::datasets
