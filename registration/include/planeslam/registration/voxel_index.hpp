#pragma once
/// A hash from integer voxel coordinates to dense indices 0, 1, 2, ... in order of first
/// insertion: open addressing with linear probing over a power-of-two table, the spatial hash of
/// Teschner et al. 2003 (as KISS-ICP and OpenVDB use) spread by a Fibonacci multiply. No
/// allocation per voxel and one cache line per probe, where std::unordered_map allocates a node
/// per entry and chases a pointer per look-up: the local map's neighbour search does 27 look-ups
/// per query.
#include <Eigen/Core>
#include <algorithm>
#include <cstdint>
#include <vector>

namespace planeslam::registration {

/// floor(x) as an Int, without a libm call (the build targets x86-64 without SSE4.1's rounding
/// instruction): the same value as static_cast<Int>(std::floor(x)) wherever that is defined.
template <typename Int = int>
inline Int FloorToInt(double x) {
  const Int truncated = static_cast<Int>(x);
  return truncated - (static_cast<double>(truncated) > x ? 1 : 0);
}

/// floor(x / size) as an int, given inverse = 1 / size, without a division: x * inverse lies within
/// three units in the last place of the quotient, so the two floors can differ only within 1e-6
/// of an integer (for quotients under 1e9), where the division decides. Always the value of
/// FloorToInt(x / size).
inline int FloorDivToInt(double x, double size, double inverse) {
  const double t = x * inverse;
  if (t > -1e9 && t < 1e9) {
    const int k = FloorToInt(t);
    const double fraction = t - static_cast<double>(k);
    if (fraction > 1e-6 && fraction < 1.0 - 1e-6) return k;
  }
  return FloorToInt(x / size);
}

/// The spatial hash of Teschner et al. 2003 of a voxel key, in 32 bits.
inline std::uint32_t SpatialHash(const Eigen::Vector3i& key) {
  return static_cast<std::uint32_t>(key.x()) * 73856093u ^
         static_cast<std::uint32_t>(key.y()) * 19349669u ^
         static_cast<std::uint32_t>(key.z()) * 83492791u;
}

/// A bitmap of occupied voxels, one bit per hash of the key (2^kLog2Bits bits): a clear bit
/// means the voxel is not occupied, a set one that it may be. Small enough to stay in a near
/// cache where a hash table of many voxels is not, it turns most look-ups of empty voxels away
/// before they probe the table.
template <int kLog2Bits>
class VoxelBitmap {
 public:
  VoxelBitmap() : words_(std::size_t{1} << (kLog2Bits - 6), 0) {}
  void Set(const Eigen::Vector3i& key) {
    const std::uint32_t b = Bit(key);
    words_[b >> 6] |= std::uint64_t{1} << (b & 63);
  }
  bool MaybeSet(const Eigen::Vector3i& key) const {
    const std::uint32_t b = Bit(key);
    return ((words_[b >> 6] >> (b & 63)) & 1u) != 0;
  }
  void Clear() { std::fill(words_.begin(), words_.end(), 0); }

 private:
  static std::uint32_t Bit(const Eigen::Vector3i& key) {
    return (SpatialHash(key) * 2654435769u) >> (32 - kLog2Bits);
  }
  std::vector<std::uint64_t> words_;
};

class VoxelIndex {
 public:
  /// Sized for about `expected` voxels (it grows when needed).
  explicit VoxelIndex(std::size_t expected = 0) { Reset(expected); }

  /// Empties the index, sized for about `expected` voxels.
  void Reset(std::size_t expected) {
    std::size_t capacity = 16;
    while (capacity < 2 * expected) capacity *= 2;
    slots_.assign(capacity, Slot{});
    shift_ = 64;
    for (std::size_t c = capacity; c > 1; c /= 2) --shift_;
    size_ = 0;
  }

  /// The index of `key`, inserted as the next one (size() before the call) when new; `inserted`
  /// says which.
  int Insert(const Eigen::Vector3i& key, bool* inserted) {
    if (2 * static_cast<std::size_t>(size_ + 1) > slots_.size()) Grow();
    std::size_t i = Home(key);
    for (;; i = (i + 1) & (slots_.size() - 1)) {
      Slot& s = slots_[i];
      if (s.index < 0) {
        s.key = key;
        s.index = size_++;
        *inserted = true;
        return s.index;
      }
      if (s.key == key) {
        *inserted = false;
        return s.index;
      }
    }
  }

  /// The index of `key`, or -1.
  int Find(const Eigen::Vector3i& key) const {
    for (std::size_t i = Home(key);; i = (i + 1) & (slots_.size() - 1)) {
      const Slot& s = slots_[i];
      if (s.index < 0) return -1;
      if (s.key == key) return s.index;
    }
  }

  int size() const { return size_; }

 private:
  struct Slot {
    Eigen::Vector3i key = Eigen::Vector3i::Zero();
    int index = -1;
  };

  std::size_t Home(const Eigen::Vector3i& v) const {
    const std::uint64_t h = static_cast<std::uint64_t>(SpatialHash(v)) ^
                            (static_cast<std::uint64_t>(static_cast<std::uint32_t>(v.z())) << 32);
    return static_cast<std::size_t>((h * 0x9E3779B97F4A7C15ull) >> shift_);
  }

  void Grow() {
    std::vector<Slot> old = std::move(slots_);
    slots_.assign(old.size() * 2, Slot{});
    --shift_;
    for (const Slot& s : old) {
      if (s.index < 0) continue;
      std::size_t i = Home(s.key);
      while (slots_[i].index >= 0) i = (i + 1) & (slots_.size() - 1);
      slots_[i] = s;
    }
  }

  std::vector<Slot> slots_;
  int shift_ = 60;
  int size_ = 0;
};

}  // namespace planeslam::registration
