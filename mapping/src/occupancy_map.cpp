#include "planeslam/mapping/occupancy_map.hpp"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <deque>
#include <fstream>
#include <functional>
#include <future>
#include <iterator>
#include <limits>
#include <utility>

#include <absl/container/flat_hash_map.h>

#include "planeslam/datasets/atomic_file.hpp"
#include "planeslam/datasets/errors.hpp"
#include "planeslam/registration/voxel_index.hpp"

#ifdef PLANESLAM_HAVE_OCTOMAP
#include <octomap/OcTree.h>
#endif

#if defined(__x86_64__)
#include <immintrin.h>
#endif

namespace planeslam::mapping {
namespace {
std::atomic<bool> vector_ray_walk{true};  // internal::SetVectorRayWalk
}  // namespace

namespace internal {
void SetVectorRayWalk(bool enabled) { vector_ray_walk.store(enabled); }
}  // namespace internal

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
  // Neighbouring points of a range image mostly share a voxel: consecutive kept points with one
  // voxel form a run, and the runs are what gets sorted.
  struct Run {
    std::uint64_t voxel;       ///< the key packed, x highest (21 bits per axis offset by 2^20)
    std::uint32_t begin, end;  ///< points[begin, end), all kept
  };
  std::vector<Run> runs;
  // Axis a's 21-bit field of a packed key.
  const auto field = [](std::uint64_t key, int a) {
    return key >> (42 - 21 * a) & ((1u << 21) - 1);
  };
  std::uint64_t lo[3] = {~std::uint64_t{0}, ~std::uint64_t{0}, ~std::uint64_t{0}}, hi[3] = {};
  for (std::size_t i = 0; i < points.size(); ++i) {
    const Eigen::Vector3f& p = points[i];
    std::uint64_t voxel_key = 0;
    bool inside = p.allFinite();
    for (int a = 0; a < 3 && inside; ++a) {
      // Inside exactly when its floor is (the bounds are integers).
      const double q = p[a] / voxel;
      inside = q >= -kHalf && q < kHalf;
      if (inside) {
        voxel_key =
            voxel_key << 21 | static_cast<std::uint64_t>(registration::FloorToInt(q) + (1 << 20));
      }
    }
    if (!inside) continue;
    const auto index = static_cast<std::uint32_t>(i);
    if (!runs.empty() && runs.back().end == index && runs.back().voxel == voxel_key) {
      runs.back().end = index + 1;
    } else {
      runs.push_back({voxel_key, index, index + 1});
      for (int a = 0; a < 3; ++a) {
        lo[a] = std::min(lo[a], field(voxel_key, a));
        hi[a] = std::max(hi[a], field(voxel_key, a));
      }
    }
  }
  if (runs.empty()) return {};
  // Repacked with as many bits per axis as the cloud's extent needs: fewer digits to sort by.
  int bits[3];
  for (int a = 0; a < 3; ++a) {
    bits[a] = 1;
    while ((std::uint64_t{1} << bits[a]) <= hi[a] - lo[a]) ++bits[a];
  }
  for (Run& run : runs) {
    std::uint64_t packed = 0;
    for (int a = 0; a < 3; ++a) packed = packed << bits[a] | (field(run.voxel, a) - lo[a]);
    run.voxel = packed;
  }
  // The runs sorted stably by voxel (radix, least significant digit first): a voxel's runs stay in
  // input order, so its points are summed in input order whatever the sort, and the centroids come
  // out in (x, y, z) voxel order.
  constexpr int kDigitBits = 11;
  std::vector<Run> buffer(runs.size());
  std::vector<std::uint32_t> start(std::size_t{1} << kDigitBits);
  for (int shift = 0; shift < bits[0] + bits[1] + bits[2]; shift += kDigitBits) {
    std::fill(start.begin(), start.end(), 0);
    const auto digit = [&](const Run& run) {
      return run.voxel >> shift & ((1u << kDigitBits) - 1);
    };
    for (const Run& run : runs) ++start[digit(run)];
    std::uint32_t sum = 0;
    for (std::uint32_t& s : start) sum += std::exchange(s, sum);
    for (const Run& run : runs) buffer[start[digit(run)]++] = run;
    runs.swap(buffer);
  }
  std::vector<Eigen::Vector3f> out;
  for (std::size_t k = 0; k < runs.size();) {
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    std::size_t count = 0;
    const std::uint64_t voxel_key = runs[k].voxel;
    for (; k < runs.size() && runs[k].voxel == voxel_key; ++k) {
      for (std::uint32_t i = runs[k].begin; i < runs[k].end; ++i) sum += points[i].cast<double>();
      count += runs[k].end - runs[k].begin;
    }
    out.push_back((sum / static_cast<double>(count)).cast<float>());
  }
  return out;
}

#ifdef PLANESLAM_HAVE_OCTOMAP

namespace {

constexpr int kBrickBits = 3;  // bricks of free cells: 8 cells a side (see CellBitmap)
constexpr std::uint32_t kBrickCells = 1u << (3 * kBrickBits);
constexpr std::uint32_t kBrickWords = kBrickCells / 64;

/// Morton index of a cell within its brick (bit b of x, y, z at 3b, 3b + 1, 3b + 2) and back, as
/// the packed key offset (x | y << 16 | z << 32), from tables.
struct MortonTables {
  std::uint32_t spread[1u << kBrickBits] = {};
  std::uint64_t offset[kBrickCells] = {};
  constexpr MortonTables() {
    for (std::uint32_t v = 0; v < (1u << kBrickBits); ++v) {
      for (int b = 0; b < kBrickBits; ++b) spread[v] |= (v >> b & 1) << (3 * b);
    }
    for (std::uint32_t m = 0; m < kBrickCells; ++m) {
      for (int b = 0; b < kBrickBits; ++b) {
        offset[m] |= std::uint64_t{m >> (3 * b) & 1} << b |
                     std::uint64_t{m >> (3 * b + 1) & 1} << (b + 16) |
                     std::uint64_t{m >> (3 * b + 2) & 1} << (b + 32);
      }
    }
  }
};
constexpr MortonTables kMorton{};

/// Morton index of the cell of packed key `key` within its brick.
std::uint32_t MortonInBrick(std::uint64_t key) {
  constexpr std::uint64_t kMask = (1u << kBrickBits) - 1;
  return kMorton.spread[key & kMask] | kMorton.spread[key >> 16 & kMask] << 1 |
         kMorton.spread[key >> 32 & kMask] << 2;
}

/// Cells whose log-odds are at the lower clamping bound, one bit each in bricks of 8 x 8 x 8:
/// a miss there changes nothing (octomap's updateNode returns early), so it is skipped before
/// the tree is searched. A free cell reached by many rays settles there after a few scans and
/// stays until a hit, so most misses of a long run fall on such cells.
class SaturatedFreeCells {
 public:
  bool Contains(std::uint64_t key) {
    const std::uint64_t* block = Block(key, false);
    const std::uint32_t m = MortonInBrick(key);
    return block != nullptr && (block[m >> 6] >> (m & 63) & 1) != 0;
  }
  void Insert(std::uint64_t key) {
    const std::uint32_t m = MortonInBrick(key);
    Block(key, true)[m >> 6] |= std::uint64_t{1} << (m & 63);
  }
  void Erase(std::uint64_t key) {
    std::uint64_t* block = Block(key, false);
    const std::uint32_t m = MortonInBrick(key);
    if (block != nullptr) block[m >> 6] &= ~(std::uint64_t{1} << (m & 63));
  }

 private:
  /// The bits of the brick holding `key`, created when asked to; null when absent. Consecutive
  /// look-ups mostly fall in one brick: the last one is kept.
  std::uint64_t* Block(std::uint64_t key, bool create) {
    constexpr std::uint64_t kCellBits = 0x0000'0007'0007'0007ULL;
    const std::uint64_t brick = key & ~kCellBits;
    if (brick != last_brick_) {
      const auto it = index_.find(brick);
      if (it != index_.end()) {
        last_block_ = it->second;
      } else if (create) {
        last_block_ = blocks_.size();
        index_.emplace(brick, last_block_);
        blocks_.emplace_back();
      } else {
        return nullptr;
      }
      last_brick_ = brick;
    }
    return blocks_[last_block_].data();
  }

  absl::flat_hash_map<std::uint64_t, std::size_t> index_;
  std::vector<std::array<std::uint64_t, kBrickWords>> blocks_;
  std::uint64_t last_brick_ = ~std::uint64_t{0};
  std::size_t last_block_ = 0;
};

}  // namespace

struct OccupancyMapBuilder::Impl {
  explicit Impl(double resolution) : tree(resolution) {}
  octomap::OcTree tree;
  SaturatedFreeCells saturated;
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

/// The cells one scan frees and occupies (packed keys, disjoint, each once), exactly the sets
/// octomap::OcTree::computeDiscreteUpdate computes: one ray per end voxel (to its centre), rays
/// longer than max_range cut there and without an end voxel, end voxels removed from the free
/// cells. It depends only on the scan, the pose and the resolution, so scans can be ray-cast in
/// parallel and applied in order.
struct ScanUpdate {
  std::vector<std::uint64_t> free_cells, occupied_cells;
  std::size_t points = 0;
};

/// One ray walked cell by cell exactly as octomap::OcTree::computeRayKeys(origin, end) walks it:
/// the same cells in the same order, with its arithmetic (Amanatides and Woo's 3D DDA).
class RayWalk {
 public:
  /// Sets up the walk and returns the first cell (the sensor's, packed) in *first; false when the
  /// ray has no cells (a coordinate outside the tree, where computeRayKeys fails, or both ends in
  /// one cell).
  bool Start(const octomap::OcTree& keys, const octomap::point3d& origin,
             const octomap::point3d& end, std::uint64_t* first) {
    octomap::OcTreeKey key, key_end;
    if (!keys.coordToKeyChecked(origin, key) || !keys.coordToKeyChecked(end, key_end)) {
      return false;
    }
    if (key == key_end) return false;
    cell_ = *first = Pack(key);
    end_cell_ = Pack(key_end);
    octomap::point3d direction = end - origin;
    length_ = static_cast<float>(direction.norm());
    direction /= length_;
    const double resolution = keys.getResolution();
    for (int i = 0; i < 3; ++i) {
      const int step = direction(i) > 0.0 ? 1 : (direction(i) < 0.0 ? -1 : 0);
      // A step in the packed key: no carry or borrow crosses fields, keys stay within the tree.
      step_[i] = static_cast<std::uint64_t>(static_cast<std::int64_t>(step)) << (16 * i);
      if (step != 0) {
        double border = keys.keyToCoord(key[i]);
        border += static_cast<float>(step * resolution * 0.5);
        t_max_[i] = (border - origin(i)) / direction(i);
        t_delta_[i] = resolution / std::fabs(direction(i));
      } else {
        t_max_[i] = t_delta_[i] = std::numeric_limits<double>::max();
      }
    }
    axis_ = NextAxis();
    return true;
  }
  /// Steps into the next cell and returns it in *cell; false when the walk has ended.
  bool Advance(std::uint64_t* cell) {
    cell_ += step_[axis_];
    t_max_[axis_] += t_delta_[axis_];
    if (cell_ == end_cell_) return false;
    axis_ = NextAxis();
    // Past the end point without reaching its cell (rounding): the walk stops, as octomap's does.
    if (t_max_[axis_] > length_) return false;
    *cell = cell_;
    return true;
  }

 private:
  // The axis whose cell border comes next, with octomap's tie-breaking; its t_max is the smallest,
  // the distance at which the ray leaves the cell it is in. Selects, not branches: the axis
  // changes unpredictably along a ray.
  int NextAxis() const {
    const int first = t_max_[0] < t_max_[1] ? 0 : 1;
    return t_max_[first] < t_max_[2] ? first : 2;
  }

  std::uint64_t cell_ = 0, end_cell_ = 0;  // packed keys
  std::uint64_t step_[3] = {0, 0, 0};      // packed, two's complement for -1
  double t_max_[3] = {0, 0, 0}, t_delta_[3] = {0, 0, 0};
  float length_ = 0;
  int axis_ = 0;

  friend class RayLanes;
};

/// WalkRays (below) without vector instructions. A walk is a chain of dependent steps, so kLanes
/// rays are walked side by side for the processor to overlap them.
template <typename Visit>
void WalkRaysScalar(const octomap::OcTree& keys, const octomap::point3d& origin,
                    const std::vector<octomap::point3d>& ends, Visit&& visit) {
  constexpr int kLanes = 8;
  RayWalk lanes[kLanes];
  bool active[kLanes] = {};
  std::size_t next = 0;
  std::uint64_t cell;
  const auto start = [&](int lane) {
    while (next < ends.size()) {
      if (lanes[lane].Start(keys, origin, ends[next++], &cell)) {
        visit(cell);
        return true;
      }
    }
    return false;
  };
  int running = 0;
  for (int lane = 0; lane < kLanes; ++lane) running += active[lane] = start(lane);
  while (running > 0) {
    for (int lane = 0; lane < kLanes; ++lane) {
      if (!active[lane]) continue;
      if (lanes[lane].Advance(&cell)) {
        visit(cell);
      } else if (!(active[lane] = start(lane))) {
        --running;
      }
    }
  }
}

#if defined(__x86_64__)
bool HasAvx2() {
  static const bool avx2 = __builtin_cpu_supports("avx2");
  return avx2 && vector_ray_walk.load(std::memory_order_relaxed);
}

__attribute__((target("avx2"))) inline __m256d LoadLanes(const double* p) {
  return _mm256_load_pd(p);
}
__attribute__((target("avx2"))) inline __m256i LoadLanes(const std::uint64_t* p) {
  return _mm256_load_si256(reinterpret_cast<const __m256i*>(p));
}

/// Four RayWalks in the lanes of AVX2 registers, stepped together: each lane takes exactly the
/// scalar walk's steps (the same double additions and comparisons, octomap's tie-breaking), so
/// the lanes visit the same cells, in another order across rays.
class RayLanes {
 public:
  /// Loads lane `lane` from a started walk, or parks it (no steps, never visits) when null.
  void Set(int lane, const RayWalk* walk) {
    for (int a = 0; a < 3; ++a) {
      t_[a][lane] = walk ? walk->t_max_[a] : 0.0;
      delta_[a][lane] = walk ? walk->t_delta_[a] : 0.0;
      step_[a][lane] = walk ? walk->step_[a] : 0;
      axis_[a][lane] = walk && walk->axis_ == a ? ~std::uint64_t{0} : 0;
    }
    cell_[lane] = walk ? walk->cell_ : 0;
    end_[lane] = walk ? walk->end_cell_ : 1;
    length_[lane] = walk ? walk->length_ : 0.0;
    active_ &= ~(1u << lane);
    if (walk) active_ |= 1u << lane;
  }
  unsigned active() const { return active_; }

  /// The lanes' current cells (packed keys), aligned for a vector load.
  const std::uint64_t* cells() const { return cell_; }

  /// One step of every lane (RayWalk::Advance) into the cells(); returns the lanes whose walk
  /// goes on (their cell is to be visited) and sets *ended to the active lanes whose walk has
  /// ended.
  __attribute__((target("avx2"))) unsigned Advance(unsigned* ended) {
    const __m256i mx = LoadLanes(axis_[0]), my = LoadLanes(axis_[1]), mz = LoadLanes(axis_[2]);
    __m256i cell =
        _mm256_add_epi64(LoadLanes(cell_),
                         _mm256_or_si256(_mm256_or_si256(_mm256_and_si256(LoadLanes(step_[0]), mx),
                                                         _mm256_and_si256(LoadLanes(step_[1]), my)),
                                         _mm256_and_si256(LoadLanes(step_[2]), mz)));
    // t + 0.0 is t: the lanes not stepping along an axis keep their t exactly.
    const __m256d tx = _mm256_add_pd(LoadLanes(t_[0]),
                                     _mm256_and_pd(LoadLanes(delta_[0]), _mm256_castsi256_pd(mx)));
    const __m256d ty = _mm256_add_pd(LoadLanes(t_[1]),
                                     _mm256_and_pd(LoadLanes(delta_[1]), _mm256_castsi256_pd(my)));
    const __m256d tz = _mm256_add_pd(LoadLanes(t_[2]),
                                     _mm256_and_pd(LoadLanes(delta_[2]), _mm256_castsi256_pd(mz)));
    const __m256i at_end = _mm256_cmpeq_epi64(cell, LoadLanes(end_));
    // NextAxis: first = t0 < t1 ? 0 : 1, then first if t[first] < t2, else 2.
    const __m256d x_first = _mm256_cmp_pd(tx, ty, _CMP_LT_OQ);
    const __m256d t_first = _mm256_blendv_pd(ty, tx, x_first);
    const __m256d not_z = _mm256_cmp_pd(t_first, tz, _CMP_LT_OQ);
    const __m256d t_next = _mm256_blendv_pd(tz, t_first, not_z);
    const __m256d past = _mm256_cmp_pd(t_next, LoadLanes(length_), _CMP_GT_OQ);
    _mm256_store_si256(reinterpret_cast<__m256i*>(axis_[0]),
                       _mm256_castpd_si256(_mm256_and_pd(x_first, not_z)));
    _mm256_store_si256(reinterpret_cast<__m256i*>(axis_[1]),
                       _mm256_castpd_si256(_mm256_andnot_pd(x_first, not_z)));
    _mm256_store_si256(reinterpret_cast<__m256i*>(axis_[2]),
                       _mm256_castpd_si256(_mm256_cmp_pd(t_first, tz, _CMP_NLT_UQ)));
    _mm256_store_pd(t_[0], tx);
    _mm256_store_pd(t_[1], ty);
    _mm256_store_pd(t_[2], tz);
    _mm256_store_si256(reinterpret_cast<__m256i*>(cell_), cell);
    const unsigned stop = static_cast<unsigned>(_mm256_movemask_pd(_mm256_castsi256_pd(at_end))) |
                          static_cast<unsigned>(_mm256_movemask_pd(past));
    *ended = stop & active_;
    return ~stop & active_;
  }

 private:
  alignas(32) double t_[3][4] = {};
  alignas(32) double delta_[3][4] = {};
  alignas(32) std::uint64_t step_[3][4] = {};
  alignas(32) std::uint64_t axis_[3][4] = {};  // all ones on the axis stepped next
  alignas(32) std::uint64_t cell_[4] = {};
  alignas(32) std::uint64_t end_[4] = {1, 1, 1, 1};
  alignas(32) double length_[4] = {};
  unsigned active_ = 0;
};

/// WalkRaysScalar with two sets of four lanes stepped by RayLanes: a ray's first cell goes to
/// visit(key), the cells stepped into to visit_lanes(keys[4], lanes to visit).
template <typename Visit, typename VisitLanes>
__attribute__((target("avx2"))) void WalkRaysAvx2(const octomap::OcTree& keys,
                                                  const octomap::point3d& origin,
                                                  const std::vector<octomap::point3d>& ends,
                                                  Visit&& visit, VisitLanes&& visit_lanes) {
  constexpr int kGroups = 2;
  RayLanes groups[kGroups];
  RayWalk walk;
  std::size_t next = 0;
  std::uint64_t first;
  const auto start = [&](RayLanes& lanes, int lane) {
    while (next < ends.size()) {
      if (walk.Start(keys, origin, ends[next++], &first)) {
        visit(first);
        lanes.Set(lane, &walk);
        return;
      }
    }
    lanes.Set(lane, nullptr);
  };
  for (RayLanes& lanes : groups) {
    for (int lane = 0; lane < 4; ++lane) start(lanes, lane);
  }
  for (;;) {
    unsigned any = 0;
    for (RayLanes& lanes : groups) {
      if (lanes.active() == 0) continue;
      any = 1;
      unsigned ended = 0;
      const unsigned go = lanes.Advance(&ended);
      visit_lanes(lanes.cells(), go);
      for (; ended != 0; ended &= ended - 1) start(lanes, __builtin_ctz(ended));
    }
    if (!any) return;
  }
}
#endif

/// Visits every cell computeRayKeys(origin, end) returns, for every end in `ends` (each cell as
/// often as it lies on a ray, in no particular order): with AVX2 a ray's first cell through
/// visit(packed key) and the cells stepped into four at a time through visit_lanes(keys[4],
/// lanes to visit); without it every cell through visit.
template <typename Visit, typename VisitLanes>
void WalkRays(const octomap::OcTree& keys, const octomap::point3d& origin,
              const std::vector<octomap::point3d>& ends, Visit&& visit, VisitLanes&& visit_lanes) {
#if defined(__x86_64__)
  if (HasAvx2()) return WalkRaysAvx2(keys, origin, ends, visit, visit_lanes);
#endif
  WalkRaysScalar(keys, origin, ends, visit);
}

/// A scan's free cells as one bit per cell of the box of keys its rays span. Marking a cell is a
/// bit set where a hash set needs a probe into a table of millions of keys (most rays of a scan
/// cross the same cells near the sensor). The bits are kept in bricks of 8 x 8 x 8 cells aligned
/// to the octree (each brick one node three levels above the leaves), cells in Morton order
/// within a brick: read in that order, neighbouring cells of the tree come one after another,
/// and applying them touches each node's children together.
class CellBitmap {
 public:
  /// Largest bitmap; a scan whose box needs more (far points and no max_range, rays sparse in
  /// the box) goes through a hash set instead.
  static constexpr std::uint64_t kMaxBits = std::uint64_t{1} << 28;  // 32 MB, kept per thread

  /// Sizes the bitmap to the bricks covering the box [lo, hi] (inclusive) and clears it; false
  /// when it is too large.
  bool Reset(const octomap::OcTreeKey& lo, const octomap::OcTreeKey& hi) {
    std::uint64_t bricks = 1;
    for (int a = 0; a < 3; ++a) {
      brick_lo_[a] = lo[a] >> kBrickBits;
      bricks_[a] = (static_cast<std::uint32_t>(hi[a]) >> kBrickBits) - brick_lo_[a] + 1;
      bricks *= bricks_[a];
    }
    if (bricks * kBrickCells > kMaxBits) return false;
    words_.assign(bricks * kBrickWords, 0);
    outside_.clear();
    return true;
  }
  void Set(std::uint64_t key) {
    std::uint64_t bit;
    if (Bit(key, &bit)) words_[bit >> 6] |= std::uint64_t{1} << (bit & 63);
    else outside_.push_back(key);
  }
#if !defined(__x86_64__)
  /// Set of the keys in `lanes` of `keys` (WalkRays visits one cell at a time without AVX2).
  void SetLanes(const std::uint64_t keys[4], unsigned lanes) {
    for (; lanes != 0; lanes &= lanes - 1) Set(keys[__builtin_ctz(lanes)]);
  }
#else
  /// Set of the keys in `lanes` of `keys` (AVX2): Bit for four keys at once.
  __attribute__((target("avx2"))) void SetLanes(const std::uint64_t keys[4], unsigned lanes) {
    const __m256i key = LoadLanes(keys);
    const __m256i field = _mm256_set1_epi64x(0xffff), low = _mm256_set1_epi64x(7);
    __m256i coordinate[3], brick[3];
    __m256i inside = _mm256_set1_epi64x(-1);
    for (int a = 0; a < 3; ++a) {
      coordinate[a] = _mm256_and_si256(_mm256_srli_epi64(key, 16 * a), field);
      brick[a] = _mm256_sub_epi64(_mm256_srli_epi64(coordinate[a], kBrickBits),
                                  _mm256_set1_epi64x(brick_lo_[a]));
      // 0 <= brick < bricks: the scalar Bit's unsigned compare.
      inside = _mm256_andnot_si256(_mm256_cmpgt_epi64(_mm256_setzero_si256(), brick[a]), inside);
      inside =
          _mm256_and_si256(_mm256_cmpgt_epi64(_mm256_set1_epi64x(bricks_[a]), brick[a]), inside);
    }
    const __m256i index = _mm256_add_epi64(
        _mm256_mul_epu32(
            _mm256_add_epi64(_mm256_mul_epu32(brick[2], _mm256_set1_epi64x(bricks_[1])), brick[1]),
            _mm256_set1_epi64x(bricks_[0])),
        brick[0]);
    // Morton within the brick: bit b of the axis a coordinate at 3b + a.
    __m256i morton = _mm256_setzero_si256();
    for (int a = 0; a < 3; ++a) {
      const __m256i v = _mm256_and_si256(coordinate[a], low);
      const __m256i spread = _mm256_or_si256(
          _mm256_and_si256(v, _mm256_set1_epi64x(1)),
          _mm256_or_si256(_mm256_slli_epi64(_mm256_and_si256(v, _mm256_set1_epi64x(2)), 2),
                          _mm256_slli_epi64(_mm256_and_si256(v, _mm256_set1_epi64x(4)), 4)));
      morton = _mm256_or_si256(morton, _mm256_slli_epi64(spread, a));
    }
    alignas(32) std::uint64_t bits[4];
    _mm256_store_si256(reinterpret_cast<__m256i*>(bits),
                       _mm256_or_si256(_mm256_slli_epi64(index, 3 * kBrickBits), morton));
    const auto in_box = static_cast<unsigned>(_mm256_movemask_pd(_mm256_castsi256_pd(inside)));
    for (unsigned set = lanes & in_box; set != 0; set &= set - 1) {
      const std::uint64_t bit = bits[__builtin_ctz(set)];
      words_[bit >> 6] |= std::uint64_t{1} << (bit & 63);
    }
    for (unsigned out = lanes & ~in_box; out != 0; out &= out - 1) {
      outside_.push_back(keys[__builtin_ctz(out)]);
    }
  }
#endif
  void Clear(std::uint64_t key) {
    std::uint64_t bit;
    if (Bit(key, &bit)) words_[bit >> 6] &= ~(std::uint64_t{1} << (bit & 63));
  }
  /// The set cells, brick by brick (z, y, x) and in Morton order within a brick, then the cells
  /// outside the box (a ray rounding past its end cell; none of them is an end cell, since the
  /// box holds every end cell).
  std::vector<std::uint64_t> Keys() const {
    std::size_t count = outside_.size();
    for (std::uint64_t word : words_) count += static_cast<std::size_t>(__builtin_popcountll(word));
    std::vector<std::uint64_t> keys;
    keys.reserve(count);
    std::size_t w = 0;
    for (std::uint32_t bz = 0; bz < bricks_[2]; ++bz) {
      for (std::uint32_t by = 0; by < bricks_[1]; ++by) {
        for (std::uint32_t bx = 0; bx < bricks_[0]; ++bx) {
          const std::uint64_t corner = Pack(octomap::OcTreeKey(
              static_cast<octomap::key_type>((brick_lo_[0] + bx) << kBrickBits),
              static_cast<octomap::key_type>((brick_lo_[1] + by) << kBrickBits),
              static_cast<octomap::key_type>((brick_lo_[2] + bz) << kBrickBits)));
          for (std::uint32_t k = 0; k < kBrickWords; ++k, ++w) {
            for (std::uint64_t bits = words_[w]; bits != 0; bits &= bits - 1) {
              keys.push_back(corner | CellOffset(k * 64 + __builtin_ctzll(bits)));
            }
          }
        }
      }
    }
    keys.insert(keys.end(), outside_.begin(), outside_.end());
    std::sort(keys.end() - static_cast<std::ptrdiff_t>(outside_.size()), keys.end());
    keys.erase(std::unique(keys.end() - static_cast<std::ptrdiff_t>(outside_.size()), keys.end()),
               keys.end());
    return keys;
  }

 private:
  static std::uint64_t CellOffset(std::uint32_t m) { return kMorton.offset[m]; }
  bool Bit(std::uint64_t key, std::uint64_t* bit) const {
    std::uint32_t brick[3];
    for (int a = 0; a < 3; ++a) {
      // Wraps when below the box: one compare.
      const auto coordinate = static_cast<std::uint32_t>(key >> (16 * a) & 0xffff);
      brick[a] = (coordinate >> kBrickBits) - brick_lo_[a];
      if (brick[a] >= bricks_[a]) return false;
    }
    const std::uint64_t index =
        (std::uint64_t{brick[2]} * bricks_[1] + brick[1]) * bricks_[0] + brick[0];
    *bit = index * kBrickCells + MortonInBrick(key);
    return true;
  }

  std::uint32_t brick_lo_[3] = {0, 0, 0};
  std::uint32_t bricks_[3] = {0, 0, 0};
  std::vector<std::uint64_t> words_;
  std::vector<std::uint64_t> outside_;
};

/// A scan's rays: from the sensor to the centre of each end voxel, or to max_range along it.
struct ScanRays {
  octomap::point3d origin;
  std::vector<octomap::point3d> ends;
  std::vector<std::uint64_t> hits;  ///< end voxels within max_range (ascending)
  octomap::OcTreeKey lo, hi;        ///< box of the keys of the sensor and every ray end
};

ScanRays CollectRays(const octomap::OcTree& keys, const OccupancyMapConfig& config,
                     const std::vector<Eigen::Vector3f>& kept, const Pose& T_world_sensor) {
  const Eigen::Matrix3f R = T_world_sensor.linear().cast<float>();
  const Eigen::Vector3f t = T_world_sensor.translation().cast<float>();
  ScanRays rays;
  rays.origin = octomap::point3d(t.x(), t.y(), t.z());
  // Discretized: one ray per end voxel, cast to the voxel's centre.
  PackedKeySet ends;
  for (const auto& p : kept) {
    const Eigen::Vector3f w = R * p + t;
    ends.Insert(Pack(keys.coordToKey(octomap::point3d(w.x(), w.y(), w.z()))));
  }
  const double max_range = config.max_range > 0 ? config.max_range : -1.0;
  octomap::OcTreeKey key;
  rays.lo = rays.hi = keys.coordToKey(rays.origin);
  const auto extend = [&](const octomap::point3d& p) {
    if (!keys.coordToKeyChecked(p, key)) return;
    for (int a = 0; a < 3; ++a) {
      rays.lo[a] = std::min(rays.lo[a], key[a]);
      rays.hi[a] = std::max(rays.hi[a], key[a]);
    }
  };
  for (std::uint64_t end_key : ends.TakeSorted()) {
    const octomap::point3d p = keys.keyToCoord(Unpack(end_key));
    if (max_range < 0.0 || (p - rays.origin).norm() <= max_range) {
      if (keys.coordToKeyChecked(p, key)) rays.hits.push_back(Pack(key));
      rays.ends.push_back(p);
    } else {
      const octomap::point3d direction = (p - rays.origin).normalized();
      rays.ends.push_back(rays.origin + direction * static_cast<float>(max_range));
    }
    extend(rays.ends.back());
  }
  // Already ascending unless a centre's key differs from its voxel's (it does not at any range
  // a tree holds); sorting makes the set operations safe regardless.
  std::sort(rays.hits.begin(), rays.hits.end());
  rays.hits.erase(std::unique(rays.hits.begin(), rays.hits.end()), rays.hits.end());
  return rays;
}

/// Free cells of the rays through a hash set, for scans whose box is too large for a bitmap.
std::vector<std::uint64_t> FreeCellsBySet(const octomap::OcTree& keys, const ScanRays& rays) {
  PackedKeySet free_cells;
  const auto insert = [&](std::uint64_t cell) { free_cells.Insert(cell); };
  WalkRays(keys, rays.origin, rays.ends, insert,
           [&](const std::uint64_t cells[4], unsigned lanes) {
             for (; lanes != 0; lanes &= lanes - 1) insert(cells[__builtin_ctz(lanes)]);
           });
  std::vector<std::uint64_t> cells = free_cells.TakeSorted();
  std::vector<std::uint64_t> kept;
  kept.reserve(cells.size());
  std::set_difference(cells.begin(), cells.end(), rays.hits.begin(), rays.hits.end(),
                      std::back_inserter(kept));
  return kept;
}

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
  // A tree only for its key arithmetic (no nodes are created in it).
  const octomap::OcTree keys(config.resolution);
  ScanRays rays = CollectRays(keys, config, kept, T_world_sensor);
  ScanUpdate update;
  // Kept per thread: clearing memory already mapped is cheaper than mapping it afresh.
  thread_local CellBitmap bitmap;
  if (bitmap.Reset(rays.lo, rays.hi)) {
    WalkRays(
        keys, rays.origin, rays.ends, [&](std::uint64_t cell) { bitmap.Set(cell); },
        [&](const std::uint64_t cells[4], unsigned lanes) { bitmap.SetLanes(cells, lanes); });
    for (std::uint64_t hit : rays.hits) bitmap.Clear(hit);
    update.free_cells = bitmap.Keys();
  } else {
    update.free_cells = FreeCellsBySet(keys, rays);
  }
  update.occupied_cells = std::move(rays.hits);
  update.points = kept.size();
  return update;
}

/// Adds `update` to the log-odds of the leaves at `keys`, exactly as
/// octomap::OcTree::updateNode(key, update, lazy_eval = true) does key by key: the same early
/// abort at a clamped leaf or pruned node, the same expansion of pruned nodes, the same new nodes.
/// Instead of descending from the root twice per key (updateNode searches first), it descends
/// once, from the deepest node the previous key's path shares: cells in brick or ascending order
/// share all but their last few levels.
///
/// Misses on cells in `saturated` are skipped (no change), and `saturated` is kept up to date.
void ApplyLazily(octomap::OcTree& tree, const std::vector<std::uint64_t>& keys, float update,
                 SaturatedFreeCells& saturated) {
  constexpr int kDepth = 16;
  static_assert(sizeof(octomap::key_type) * 8 == kDepth, "an OcTree key has one bit per level");
  const float clamp_min = tree.getClampingThresMinLog();
  const float clamp_max = tree.getClampingThresMaxLog();
  const auto clamped = [&](const octomap::OcTreeNode* node) {
    return (update >= 0 && node->getLogOdds() >= clamp_max) ||
           (update <= 0 && node->getLogOdds() <= clamp_min);
  };
  octomap::OcTreeNode* path[kDepth + 1];
  int known = 0;  // path[0, known) hold the previous key's nodes from the root down
  std::uint64_t previous = 0;
  for (std::uint64_t packed : keys) {
    if (update > 0) {
      saturated.Erase(packed);
    } else if (saturated.Contains(packed)) {
      continue;  // a miss on a cell at the lower bound changes nothing
    }
    const octomap::OcTreeKey key = Unpack(packed);
    if (tree.getRoot() == nullptr) {  // an empty tree: updateNode creates the root
      tree.updateNode(key, update, true);
      continue;
    }
    // Levels shared with the previous key: its leading equal bits in all three coordinates.
    const std::uint64_t diff = packed ^ previous;
    const unsigned differing = static_cast<unsigned>((diff | diff >> 16 | diff >> 32) & 0xffff);
    const int shared = differing == 0 ? kDepth : __builtin_clz(differing) - 16;
    path[0] = tree.getRoot();
    int depth = std::min(shared, std::max(known - 1, 0));
    octomap::OcTreeNode* node = path[depth];
    bool created = false, aborted = false;
    for (; depth < kDepth; path[++depth] = node) {
      const unsigned child = octomap::computeChildIdx(key, kDepth - 1 - depth);
      if (!tree.nodeChildExists(node, child)) {
        if (!created && !tree.nodeHasChildren(node)) {
          // A pruned node stands for the cell: updateNode's search stops at it.
          if (clamped(node)) {
            aborted = true;
            break;
          }
          tree.expandNode(node);
        } else {
          tree.createNodeChild(node, child);
          created = true;
        }
      }
      node = tree.getNodeChild(node, child);
    }
    known = depth + 1;
    previous = packed;
    if (!aborted && (created || !clamped(node))) tree.updateNodeLogOdds(node, update);
    if (update <= 0 && node->getLogOdds() <= clamp_min) saturated.Insert(packed);
  }
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
    ApplyLazily(impl_->tree, update.free_cells, impl_->tree.getProbMissLog(), impl_->saturated);
    ApplyLazily(impl_->tree, update.occupied_cells, impl_->tree.getProbHitLog(), impl_->saturated);
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
