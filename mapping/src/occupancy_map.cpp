#include "planeslam/mapping/occupancy_map.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <deque>
#include <fstream>
#include <functional>
#include <future>
#include <limits>
#include <utility>

#include "planeslam/datasets/atomic_file.hpp"
#include "planeslam/datasets/errors.hpp"
#include "planeslam/registration/voxel_index.hpp"

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
  PLANESLAM_CHECK(points.size() <= static_cast<std::size_t>(std::numeric_limits<int>::max()),
                  "too many points: " << points.size());
  // Voxel indices within +-2^20 per axis, e.g. +-52 km at 5 cm; points beyond are dropped (no
  // range image reaches that far).
  constexpr double kHalf = 1 << 20;
  // Each voxel's points are summed in input order, and the centroids come out in (x, y, z) voxel
  // order, so the result does not depend on how the voxels are found. Neighbouring points of a
  // range image mostly share a voxel: the last one found is tried first.
  registration::VoxelIndex index;
  std::vector<Eigen::Vector3i> keys;
  std::vector<Eigen::Vector3d> sums;
  std::vector<int> counts;
  int last = -1;
  for (const Eigen::Vector3f& p : points) {
    if (!p.allFinite()) continue;
    Eigen::Vector3i key;
    bool inside = true;
    for (int a = 0; a < 3 && inside; ++a) {
      // Inside exactly when its floor is (the bounds are integers).
      const double q = p[a] / voxel;
      inside = q >= -kHalf && q < kHalf;
      key[a] = inside ? registration::FloorToInt(q) : 0;
    }
    if (!inside) continue;
    if (last < 0 || keys[last] != key) {
      bool inserted = false;
      last = index.Insert(key, &inserted);
      if (inserted) {
        keys.push_back(key);
        sums.push_back(Eigen::Vector3d::Zero());
        counts.push_back(0);
      }
    }
    sums[last] += p.cast<double>();
    ++counts[last];
  }
  // (x, y, z) order is the order of the keys packed into 21 bits each, offset to be non-negative:
  // the sort compares one integer, not three through an index.
  std::vector<std::pair<std::uint64_t, int>> order(keys.size());
  for (std::size_t k = 0; k < order.size(); ++k) {
    std::uint64_t packed = 0;
    for (int a = 0; a < 3; ++a) {
      packed = packed << 21 | static_cast<std::uint64_t>(keys[k][a] + (1 << 20));
    }
    order[k] = {packed, static_cast<int>(k)};
  }
  std::sort(order.begin(), order.end());
  std::vector<Eigen::Vector3f> out;
  out.reserve(order.size());
  for (const auto& [packed, k] : order) out.push_back((sums[k] / counts[k]).cast<float>());
  return out;
}

#ifdef PLANESLAM_HAVE_OCTOMAP

struct OccupancyMapBuilder::Impl {
  explicit Impl(double resolution) : tree(resolution) {}
  octomap::OcTree tree;
  std::size_t frames = 0;
  std::size_t points = 0;
  bool inner_stale = false;  ///< inserted lazily since the inner nodes were last updated
  void InnerNodesUpToDate();
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

/// An OcTreeKey packed into 48 bits (x | y << 16 | z << 32).
std::uint64_t Pack(const octomap::OcTreeKey& k) {
  return std::uint64_t{k[0]} | std::uint64_t{k[1]} << 16 | std::uint64_t{k[2]} << 32;
}
octomap::OcTreeKey Unpack(std::uint64_t p) {
  return octomap::OcTreeKey(static_cast<octomap::key_type>(p & 0xffff),
                            static_cast<octomap::key_type>((p >> 16) & 0xffff),
                            static_cast<octomap::key_type>((p >> 32) & 0xffff));
}

/// Sorts the 48-bit values data[0..n) ascending: three stable counting passes over 16-bit digits
/// (several times faster than std::sort on the hundreds of thousands of cells a LiDAR scan frees),
/// alternating between data and buffer (n values each). Returns where the result lies (buffer).
std::uint64_t* RadixSort48(std::uint64_t* data, std::uint64_t* buffer, std::size_t n) {
  std::vector<std::size_t> start(1 << 16);
  for (int shift = 0; shift < 48; shift += 16) {
    std::fill(start.begin(), start.end(), 0);
    for (std::size_t i = 0; i < n; ++i) ++start[(data[i] >> shift) & 0xffff];
    std::size_t sum = 0;
    for (std::size_t& s : start) sum += std::exchange(s, sum);
    for (std::size_t i = 0; i < n; ++i) buffer[start[(data[i] >> shift) & 0xffff]++] = data[i];
    std::swap(data, buffer);
  }
  return data;
}

/// Open-addressing set of packed keys. Ray casting a scan inserts millions of keys, most of them
/// repeats near the sensor; octomap's KeySet (an unordered_set) allocates a node for every new key
/// and frees them all afterwards, which made it the largest cost of building the map.
class PackedKeySet {
 public:
  PackedKeySet() : slots_(1024, kEmpty), mask_(1023), shift_(54) {}

  void Insert(std::uint64_t key) {
    if (2 * (size_ + 1) > slots_.size()) Grow();
    for (std::size_t i = Slot(key);; i = (i + 1) & mask_) {
      if (slots_[i] == key) return;
      if (slots_[i] == kEmpty) {
        slots_[i] = key;
        ++size_;
        return;
      }
    }
  }
  bool Contains(std::uint64_t key) const {
    for (std::size_t i = Slot(key);; i = (i + 1) & mask_) {
      if (slots_[i] == key) return true;
      if (slots_[i] == kEmpty) return false;
    }
  }
  /// The keys in ascending order (neighbouring cells next to each other, so applying them in this
  /// order walks the octree with its upper levels in cache); empties the set. The keys are
  /// compacted to the front of the table and sorted with its free second half as the buffer
  /// (the table is at most half full), so sorting a large scan's cells needs no more memory.
  std::vector<std::uint64_t> TakeSorted() {
    std::size_t n = 0;
    for (std::uint64_t k : slots_) {
      if (k != kEmpty) slots_[n++] = k;
    }
    const std::uint64_t* sorted = RadixSort48(slots_.data(), slots_.data() + n, n);
    std::vector<std::uint64_t> keys(sorted, sorted + n);
    *this = PackedKeySet();
    return keys;
  }

 private:
  static constexpr std::uint64_t kEmpty = ~std::uint64_t{0};  // no packed key has the top bits
  std::size_t Slot(std::uint64_t key) const {
    return static_cast<std::size_t>((key * 0x9E3779B97F4A7C15ULL) >> shift_);
  }
  void Grow() {
    std::vector<std::uint64_t> old(2 * slots_.size(), kEmpty);
    old.swap(slots_);
    mask_ = slots_.size() - 1;
    --shift_;
    size_ = 0;
    for (std::uint64_t k : old) {
      if (k != kEmpty) Insert(k);
    }
  }

  std::vector<std::uint64_t> slots_;
  std::size_t mask_;
  int shift_;
  std::size_t size_ = 0;
};

/// The cells one scan frees and occupies (packed keys, ascending, disjoint), exactly the sets
/// octomap::OcTree::computeDiscreteUpdate computes: one ray per end voxel (to its centre), rays
/// longer than max_range cut there and without an end voxel, end voxels removed from the free
/// cells. It depends only on the scan, the pose and the resolution, so scans can be ray-cast in
/// parallel and applied in order.
struct ScanUpdate {
  std::vector<std::uint64_t> free_cells, occupied_cells;
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
  const Eigen::Matrix3f R = T_world_sensor.linear().cast<float>();
  const Eigen::Vector3f t = T_world_sensor.translation().cast<float>();
  const octomap::point3d origin(t.x(), t.y(), t.z());
  // A tree only for its key arithmetic and ray casting (no nodes are created in it).
  const octomap::OcTree keys(config.resolution);
  // Discretized: one ray per end voxel, cast to the voxel's centre.
  PackedKeySet ends;
  for (const auto& p : kept) {
    const Eigen::Vector3f w = R * p + t;
    ends.Insert(Pack(keys.coordToKey(octomap::point3d(w.x(), w.y(), w.z()))));
  }
  const double max_range = config.max_range > 0 ? config.max_range : -1.0;
  PackedKeySet free_cells, occupied_cells;
  octomap::KeyRay ray;
  for (std::uint64_t end_key : ends.TakeSorted()) {
    const octomap::point3d p = keys.keyToCoord(Unpack(end_key));
    octomap::point3d ray_end = p;
    const bool in_range = max_range < 0.0 || (p - origin).norm() <= max_range;
    if (in_range) {
      octomap::OcTreeKey key;
      if (keys.coordToKeyChecked(p, key)) occupied_cells.Insert(Pack(key));
    } else {
      const octomap::point3d direction = (p - origin).normalized();
      ray_end = origin + direction * static_cast<float>(max_range);
    }
    if (keys.computeRayKeys(origin, ray_end, ray)) {
      for (const octomap::OcTreeKey& k : ray) free_cells.Insert(Pack(k));
    }
  }
  ScanUpdate update;
  update.free_cells = free_cells.TakeSorted();
  update.free_cells.erase(
      std::remove_if(update.free_cells.begin(), update.free_cells.end(),
                     [&](std::uint64_t k) { return occupied_cells.Contains(k); }),
      update.free_cells.end());
  update.occupied_cells = occupied_cells.TakeSorted();
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
  // While one scan is applied, the next `threads` are ray-cast (a scan's ray casting takes about
  // twice as long as applying it, so the applying thread mostly waits): every core is busy, and
  // at most `threads + 1` scans' cell sets (tens of MB each for a LiDAR scan) are held at once.
  std::deque<std::future<ScanUpdate>> ahead;
  std::size_t next = 0;
  const auto launch = [&](std::launch policy) {
    ahead.push_back(std::async(policy, ComputeScanUpdate, std::cref(config_),
                               std::cref(*scans[next]), std::cref(poses[next])));
    ++next;
  };
  while (next < scans.size() || !ahead.empty()) {
    if (ahead.empty()) launch(std::launch::deferred);  // nothing to overlap with: this thread
    const ScanUpdate update = ahead.front().get();
    ahead.pop_front();
    while (next < scans.size() && threads > 1 && ahead.size() < threads) {
      launch(std::launch::async);
    }
    // Applied as insertPointCloud does, free cells then occupied ones, but lazily: each cell is
    // updated at most once per scan, so the order within a scan does not matter, and the inner
    // nodes (maxima of their children) are brought up to date once (InnerNodesUpToDate) instead of
    // along the path of every cell. The leaves, and so the pruned tree, are the same.
    for (std::uint64_t key : update.free_cells) impl_->tree.updateNode(Unpack(key), false, true);
    for (std::uint64_t key : update.occupied_cells) impl_->tree.updateNode(Unpack(key), true, true);
    ++impl_->frames;
    impl_->points += update.points;
    impl_->inner_stale = true;
  }
}

void OccupancyMapBuilder::Impl::InnerNodesUpToDate() {
  if (!inner_stale) return;
  tree.updateInnerOccupancy();
  inner_stale = false;
}

void OccupancyMapBuilder::Write(const std::string& path) const {
  // Pruning merges children with equal values only: occupancy is unchanged and the file smaller.
  impl_->InnerNodesUpToDate();
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
