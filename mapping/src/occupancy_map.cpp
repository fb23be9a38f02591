#include "planeslam/mapping/occupancy_map.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <deque>
#include <functional>
#include <future>
#include <fstream>
#include <unordered_map>

#include "planeslam/datasets/atomic_file.hpp"
#include "planeslam/datasets/errors.hpp"

#ifdef PLANESLAM_HAVE_OCTOMAP
#include <octomap/OcTree.h>
#endif

namespace planeslam::mapping {

std::vector<std::string> OccupancyMapConfig::Validate() const {
  std::vector<std::string> problems;
  if (!(resolution > 0)) problems.push_back("resolution must be > 0");
  if (!std::isfinite(max_range)) problems.push_back("max_range must be finite (<= 0 for none)");
  if (!(downsample_voxel >= 0)) problems.push_back("downsample_voxel must be >= 0");
  if (!(prob_hit > 0.5 && prob_hit < 1.0)) problems.push_back("prob_hit must be in (0.5, 1)");
  if (!(prob_miss > 0.0 && prob_miss < 0.5)) problems.push_back("prob_miss must be in (0, 0.5)");
  return problems;
}

std::vector<Eigen::Vector3f> VoxelDownsample(const std::vector<Eigen::Vector3f>& points,
                                             double voxel) {
  PLANESLAM_CHECK(voxel > 0, "voxel must be > 0, got " << voxel);
  // Voxel indices packed in 21 bits per axis (offset 2^20): +-2^20 voxels, e.g. +-52 km at 5 cm;
  // points beyond are dropped (no range image reaches that far).
  constexpr std::int64_t kHalf = std::int64_t{1} << 20;
  std::unordered_map<std::uint64_t, std::pair<Eigen::Vector3d, int>> cells;
  cells.reserve(points.size() / 4 + 16);
  for (const auto& p : points) {
    if (!p.allFinite()) continue;
    std::uint64_t key = 0;
    bool inside = true;
    for (int a = 0; a < 3; ++a) {
      const double idx = std::floor(p[a] / voxel);
      if (!(idx >= -kHalf && idx < kHalf)) {
        inside = false;
        break;
      }
      key = (key << 21) | static_cast<std::uint64_t>(static_cast<std::int64_t>(idx) + kHalf);
    }
    if (!inside) continue;
    auto& c = cells[key];
    if (c.second == 0) c.first.setZero();
    c.first += p.cast<double>();
    ++c.second;
  }
  std::vector<std::pair<std::uint64_t, Eigen::Vector3f>> sorted;
  sorted.reserve(cells.size());
  for (const auto& [key, c] : cells) sorted.emplace_back(key, (c.first / c.second).cast<float>());
  std::sort(sorted.begin(), sorted.end(),
            [](const auto& a, const auto& b) { return a.first < b.first; });
  std::vector<Eigen::Vector3f> out;
  out.reserve(sorted.size());
  for (const auto& kv : sorted) out.push_back(kv.second);
  return out;
}

#ifdef PLANESLAM_HAVE_OCTOMAP

struct OccupancyMapBuilder::Impl {
  explicit Impl(double resolution) : tree(resolution) {}
  octomap::OcTree tree;
  std::size_t frames = 0;
  std::size_t points = 0;
};

bool OccupancyMapBuilder::available() { return true; }

OccupancyMapBuilder::OccupancyMapBuilder(const OccupancyMapConfig& config) : config_(config) {
  const auto problems = config_.Validate();
  PLANESLAM_CHECK(problems.empty(), "invalid OccupancyMapConfig: " << problems.front());
  impl_ = std::make_unique<Impl>(config_.resolution);
  impl_->tree.setProbHit(config_.prob_hit);
  impl_->tree.setProbMiss(config_.prob_miss);
}

namespace {

/// The cells one scan frees and occupies, as octomap::OcTree::insertPointCloud computes them. It
/// depends only on the scan, the pose and the resolution, so scans can be ray-cast in parallel,
/// each in its own scratch tree (a tree's ray buffer is not shared), and applied in order.
struct ScanUpdate {
  octomap::KeySet free_cells, occupied_cells;
  std::size_t points = 0;
};

ScanUpdate ComputeScanUpdate(const OccupancyMapConfig& config,
                             const std::vector<Eigen::Vector3f>& points_sensor,
                             const Pose& T_world_sensor) {
  PLANESLAM_CHECK(T_world_sensor.matrix().allFinite(), "pose not finite");
  std::vector<Eigen::Vector3f> kept;
  if (config.downsample_voxel > 0) {
    kept = VoxelDownsample(points_sensor, config.downsample_voxel);
  } else {
    kept.reserve(points_sensor.size());
    for (const auto& p : points_sensor) {
      if (p.allFinite()) kept.push_back(p);
    }
  }
  octomap::Pointcloud scan;
  scan.reserve(kept.size());
  const Eigen::Matrix3f R = T_world_sensor.linear().cast<float>();
  const Eigen::Vector3f t = T_world_sensor.translation().cast<float>();
  for (const auto& p : kept) {
    const Eigen::Vector3f w = R * p + t;
    scan.push_back(w.x(), w.y(), w.z());
  }
  const octomap::point3d origin(t.x(), t.y(), t.z());
  // Discretized: one ray per end voxel (the downsampled points are already about one per voxel
  // when downsample_voxel ~ resolution; with downsampling off it removes the duplicates).
  octomap::OcTree scratch(config.resolution);
  ScanUpdate update;
  scratch.computeDiscreteUpdate(scan, origin, update.free_cells, update.occupied_cells,
                                config.max_range > 0 ? config.max_range : -1.0);
  update.points = kept.size();
  return update;
}

}  // namespace

void OccupancyMapBuilder::Insert(const std::vector<Eigen::Vector3f>& points_sensor,
                                 const Pose& T_world_sensor) {
  InsertAll({&points_sensor}, {T_world_sensor}, 1);
}

void OccupancyMapBuilder::InsertAll(const std::vector<const std::vector<Eigen::Vector3f>*>& scans,
                                    const std::vector<Pose>& poses, unsigned threads) {
  PLANESLAM_CHECK(scans.size() == poses.size(), "one pose per scan");
  // At most `threads` scans are ray-cast ahead of the one being applied (memory stays bounded).
  std::deque<std::future<ScanUpdate>> ahead;
  std::size_t next = 0;
  const auto launch = [&] {
    const auto policy = threads > 1 ? std::launch::async : std::launch::deferred;
    ahead.push_back(std::async(policy, ComputeScanUpdate, std::cref(config_),
                               std::cref(*scans[next]), std::cref(poses[next])));
    ++next;
  };
  while (next < scans.size() || !ahead.empty()) {
    while (next < scans.size() && ahead.size() < std::max(1u, threads)) launch();
    const ScanUpdate update = ahead.front().get();
    ahead.pop_front();
    // Applied as insertPointCloud does: free cells, then occupied ones.
    for (const auto& key : update.free_cells) impl_->tree.updateNode(key, false, false);
    for (const auto& key : update.occupied_cells) impl_->tree.updateNode(key, true, false);
    ++impl_->frames;
    impl_->points += update.points;
  }
}

void OccupancyMapBuilder::Write(const std::string& path) const {
  // Pruning merges children with equal values only: occupancy is unchanged and the file smaller.
  impl_->tree.prune();
  datasets::AtomicOutputFile out(path, /*binary=*/true);
  // writeBinaryConst stores the maximum-likelihood state of every leaf without converting the
  // in-memory tree (writeBinary would), so later inserts keep their probabilities.
  if (!impl_->tree.writeBinaryConst(out.stream())) throw IoError(path, "OctoMap could not write");
  out.Commit();
}

OccupancyMapBuilder OccupancyMapBuilder::Load(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw IoError(path, "cannot open");
  // Check the header ourselves: OctoMap reports a bad file on stderr before returning false.
  std::string first;
  std::getline(in, first);
  if (first.rfind("# Octomap OcTree binary file", 0) != 0) {
    throw IoError(path, "not an OctoMap binary (.bt) file");
  }
  in.seekg(0);
  OccupancyMapBuilder builder;
  if (!builder.impl_->tree.readBinary(in)) throw IoError(path, "invalid OctoMap binary data");
  builder.config_.resolution = builder.impl_->tree.getResolution();
  return builder;
}

Occupancy OccupancyMapBuilder::Query(const Eigen::Vector3d& p) const {
  const octomap::OcTreeNode* node = impl_->tree.search(p.x(), p.y(), p.z());
  if (!node) return Occupancy::kUnknown;
  return impl_->tree.isNodeOccupied(node) ? Occupancy::kOccupied : Occupancy::kFree;
}

OccupancyMapStats OccupancyMapBuilder::Stats() const {
  OccupancyMapStats s;
  for (auto it = impl_->tree.begin_leafs(), end = impl_->tree.end_leafs(); it != end; ++it) {
    if (impl_->tree.isNodeOccupied(*it)) {
      ++s.occupied_leaves;
    } else {
      ++s.free_leaves;
    }
  }
  s.inserted_frames = impl_->frames;
  s.inserted_points = impl_->points;
  s.memory_bytes = impl_->tree.memoryUsage();
  return s;
}

double OccupancyMapBuilder::resolution() const { return impl_->tree.getResolution(); }

#else  // built without OctoMap

struct OccupancyMapBuilder::Impl {};

bool OccupancyMapBuilder::available() { return false; }

OccupancyMapBuilder::OccupancyMapBuilder(const OccupancyMapConfig& config) : config_(config) {
  const auto problems = config_.Validate();
  PLANESLAM_CHECK(problems.empty(), "invalid OccupancyMapConfig: " << problems.front());
}

void OccupancyMapBuilder::Insert(const std::vector<Eigen::Vector3f>&, const Pose&) {}
void OccupancyMapBuilder::InsertAll(const std::vector<const std::vector<Eigen::Vector3f>*>&,
                                    const std::vector<Pose>&, unsigned) {}

void OccupancyMapBuilder::Write(const std::string& path) const {
  throw IoError(path, "planeslam was built without OctoMap (PLANESLAM_WITH_OCTOMAP=OFF)");
}

OccupancyMapBuilder OccupancyMapBuilder::Load(const std::string& path) {
  throw IoError(path, "planeslam was built without OctoMap (PLANESLAM_WITH_OCTOMAP=OFF)");
}

Occupancy OccupancyMapBuilder::Query(const Eigen::Vector3d&) const { return Occupancy::kUnknown; }

OccupancyMapStats OccupancyMapBuilder::Stats() const { return {}; }

double OccupancyMapBuilder::resolution() const { return config_.resolution; }

#endif

OccupancyMapBuilder::~OccupancyMapBuilder() = default;
OccupancyMapBuilder::OccupancyMapBuilder(OccupancyMapBuilder&&) noexcept = default;
OccupancyMapBuilder& OccupancyMapBuilder::operator=(OccupancyMapBuilder&&) noexcept = default;

void OccupancyMapBuilder::Insert(const datasets::OrganizedCloud& cloud,
                                 const Pose& T_world_sensor) {
  std::vector<Eigen::Vector3f> points;
  points.reserve(cloud.size());
  for (const auto& p : cloud.points) {
    if (datasets::OrganizedCloud::IsValid(p) && p.allFinite()) points.push_back(p);
  }
  Insert(points, T_world_sensor);
}

}  // namespace planeslam::mapping
