#include "planeslam/datasets/tum_sequence.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>

#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/trajectory_io.hpp"
#include "reader_util.hpp"

namespace planeslam::datasets {

namespace fs = std::filesystem;

std::vector<FrameListEntry> ParseFrameList(const std::string& text, const std::string& name,
                                           int columns) {
  std::vector<FrameListEntry> entries;
  detail::LineReader reader(text, name);
  std::string_view line;
  while (reader.Next(&line)) {
    const std::string_view trimmed = detail::Trim(line);
    if (trimmed.empty() || trimmed.front() == '#') continue;
    const auto tokens = detail::SplitWhitespace(trimmed);
    if (static_cast<int>(tokens.size()) != columns) {
      throw IoError(
          name, reader.line_number(),
          "expected " + std::to_string(columns) + " columns, got " + std::to_string(tokens.size()));
    }
    FrameListEntry entry;
    if (!detail::ParseDouble(tokens[0], &entry.timestamp)) {
      throw IoError(name, reader.line_number(),
                    "expected a timestamp, got '" + std::string(tokens[0]) + "'");
    }
    entry.file = std::string(tokens[1]);
    entry.line = reader.line_number();
    if (!entries.empty() && !(entry.timestamp > entries.back().timestamp)) {
      throw IoError(
          name, reader.line_number(),
          std::string(entry.timestamp == entries.back().timestamp ? "duplicate" : "unsorted") +
              " timestamp " + std::string(tokens[0]) + " (previous line " +
              std::to_string(entries.back().line) + ")");
    }
    entries.push_back(std::move(entry));
  }
  if (entries.empty()) throw IoError(name, "lists no frames");
  return entries;
}

std::vector<std::optional<Pose>> AssociateByTime(const std::vector<double>& frame_stamps,
                                                 const Trajectory& gt, double max_difference) {
  std::vector<std::optional<Pose>> out(frame_stamps.size());
  if (gt.empty()) return out;
  for (std::size_t i = 0; i < frame_stamps.size(); ++i) {
    const double t = frame_stamps[i];
    const auto it = std::lower_bound(gt.stamps.begin(), gt.stamps.end(), t);
    std::size_t best = gt.size();
    double best_dt = std::numeric_limits<double>::infinity();
    for (auto cand : {it, it == gt.stamps.begin() ? it : it - 1}) {
      if (cand == gt.stamps.end()) continue;
      const double dt = std::abs(*cand - t);
      if (dt < best_dt) {
        best_dt = dt;
        best = static_cast<std::size_t>(cand - gt.stamps.begin());
      }
    }
    if (best < gt.size() && best_dt <= max_difference) out[i] = gt.poses[best];
  }
  return out;
}

DepthImageSequence::DepthImageSequence(std::string name, std::vector<Item> items,
                                       const PinholeIntrinsics& intrinsics, double depth_scale,
                                       double min_depth, double max_depth)
    : name_(std::move(name)),
      items_(std::move(items)),
      projector_(intrinsics, depth_scale, min_depth, max_depth),
      depth_scale_(depth_scale) {}

Frame DepthImageSequence::Load(std::size_t index) const { return LoadDecimated(index, 1); }

Frame DepthImageSequence::LoadDecimated(std::size_t index, int factor) const {
  PLANESLAM_CHECK(index < items_.size(), "frame " << index << " of " << items_.size());
  const Item& item = items_[index];
  Frame frame;
  frame.index = index;
  frame.timestamp = item.timestamp;
  frame.source = item.path;
  frame.T_world_sensor_gt = item.T_world_sensor_gt;
  std::error_code ec;
  if (!item.list.empty() && !fs::is_regular_file(item.path, ec)) {
    throw IoError(item.list, item.list_line,
                  "names '" + item.list_entry + "' which does not exist");
  }
  const Image16 depth = ReadPng16(item.path);
  PLANESLAM_CHECK(depth.data.size() == static_cast<std::size_t>(depth.width) * depth.height,
                  "image buffer size mismatch");
  projector_.Project(depth.data.data(), depth.width, depth.height, &frame.cloud, item.path,
                     factor);
  frame.decimation = factor;
  return frame;
}

double DepthImageSequence::Timestamp(std::size_t index) const {
  PLANESLAM_CHECK(index < items_.size(), "frame " << index << " of " << items_.size());
  return items_[index].timestamp;
}

std::optional<Pose> DepthImageSequence::GroundTruth(std::size_t index) const {
  PLANESLAM_CHECK(index < items_.size(), "frame " << index << " of " << items_.size());
  return items_[index].T_world_sensor_gt;
}

std::size_t DepthImageSequence::GroundTruthCount() const {
  return static_cast<std::size_t>(std::count_if(
      items_.begin(), items_.end(), [](const Item& i) { return i.T_world_sensor_gt.has_value(); }));
}

namespace {

void RequireFolder(const std::string& folder) {
  std::error_code ec;
  if (!fs::exists(folder, ec)) throw IoError(folder, "no such folder");
  if (!fs::is_directory(folder, ec)) throw IoError(folder, "not a folder");
}

std::string FolderName(const std::string& folder) {
  fs::path p = fs::path(folder).lexically_normal();
  if (p.filename().empty()) p = p.parent_path();
  return p.filename().string();
}

// Resolves every listed file against the folder. A file that is missing is a bad frame, reported
// when it is loaded, so that one missing file does not refuse the whole sequence.
std::vector<DepthImageSequence::Item> ResolveFiles(const std::vector<FrameListEntry>& entries,
                                                   const fs::path& folder,
                                                   const std::string& list_name) {
  std::vector<DepthImageSequence::Item> items;
  items.reserve(entries.size());
  for (const FrameListEntry& e : entries) {
    DepthImageSequence::Item item;
    item.timestamp = e.timestamp;
    item.path = (folder / e.file).string();
    item.list = list_name;
    item.list_line = static_cast<long>(e.line);
    item.list_entry = e.file;
    items.push_back(std::move(item));
  }
  return items;
}

void AttachGroundTruth(std::vector<DepthImageSequence::Item>* items, const fs::path& gt_path,
                       double max_difference) {
  std::error_code ec;
  if (!fs::exists(gt_path, ec)) return;
  const Trajectory gt = ReadTumTrajectory(gt_path.string());
  std::vector<double> stamps;
  stamps.reserve(items->size());
  for (const auto& item : *items) stamps.push_back(item.timestamp);
  const auto poses = AssociateByTime(stamps, gt, max_difference);
  for (std::size_t i = 0; i < items->size(); ++i) (*items)[i].T_world_sensor_gt = poses[i];
}

}  // namespace

std::unique_ptr<DepthImageSequence> OpenTumSequence(const std::string& folder,
                                                    const SensorConfig& config) {
  config.ValidateOrThrow();
  RequireFolder(folder);
  const fs::path dir(folder);
  const std::string list = (dir / "depth.txt").string();
  const auto entries =
      ParseFrameList(detail::ReadWholeFile(list, detail::MaxInputFileBytes()), list, 2);
  auto items = ResolveFiles(entries, dir, list);
  AttachGroundTruth(&items, dir / "groundtruth.txt", config.gt_max_time_difference);
  PinholeIntrinsics intrinsics = config.EffectiveIntrinsics();
  double depth_scale = config.depth_scale;
  std::error_code ec;
  if (config.intrinsics_source == "auto" && fs::exists(dir / "intrinsics.yaml", ec)) {
    const CameraFile camera = ReadCameraFile((dir / "intrinsics.yaml").string());
    intrinsics = camera.intrinsics;
    depth_scale = camera.depth_scale;
  }
  return std::make_unique<DepthImageSequence>(FolderName(folder), std::move(items), intrinsics,
                                              depth_scale, config.min_depth, config.max_depth);
}

std::unique_ptr<DepthImageSequence> OpenIclSequence(const std::string& folder,
                                                    const SensorConfig& config) {
  config.ValidateOrThrow();
  RequireFolder(folder);
  const fs::path dir(folder);
  const std::string list = (dir / "associations.txt").string();
  const auto entries =
      ParseFrameList(detail::ReadWholeFile(list, detail::MaxInputFileBytes()), list, 4);
  auto items = ResolveFiles(entries, dir, list);
  // Ground-truth stamps are the frame numbers N themselves, so an exact match is required; a
  // tolerance well below one frame keeps float printing ("12" vs "12.000000") harmless.
  AttachGroundTruth(&items, dir / "groundtruth.txt", 1e-3);
  CameraFile camera;
  std::error_code ec;
  if (config.intrinsics_source == "auto") {
    camera = fs::exists(dir / "intrinsics.yaml", ec)
                 ? ReadCameraFile((dir / "intrinsics.yaml").string())
                 : IclNuimCamera();
  } else {
    camera.intrinsics = config.EffectiveIntrinsics();
    camera.depth_scale = config.depth_scale;
  }
  return std::make_unique<DepthImageSequence>(FolderName(folder), std::move(items),
                                              camera.intrinsics, camera.depth_scale,
                                              config.min_depth, config.max_depth);
}

}  // namespace planeslam::datasets
