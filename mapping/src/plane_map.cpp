#include "planeslam/mapping/plane_map.hpp"

#include <absl/container/flat_hash_map.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

#include "planeslam/datasets/errors.hpp"
#include "planeslam/registration/voxel_index.hpp"

namespace planeslam::mapping {
namespace {

constexpr double kDegToRad = M_PI / 180.0;
/// An extent's basis is rebuilt when the plane's normal has turned by more than this since: the
/// in-plane coordinates of a point 10 m away then shift by less than 10 m * (1 - cos 1 deg) = 1.5
/// mm.
constexpr double kExtentRebuildAngleDeg = 1.0;

std::int64_t CellKey(std::int64_t i, std::int64_t j) {
  // Shifted as unsigned: a left shift of a negative signed value is undefined behaviour.
  return static_cast<std::int64_t>(static_cast<std::uint64_t>(i) << 32 ^
                                   static_cast<std::uint64_t>(static_cast<std::uint32_t>(j)));
}

std::int64_t FloorIndex(double x, double cell) {
  return registration::FloorToInt<std::int64_t>(x / cell);
}

std::int64_t CellI(std::int64_t key) { return key >> 32; }
std::int64_t CellJ(std::int64_t key) { return static_cast<std::int32_t>(key & 0xffffffff); }

/// A grid's cells over the box of the occupied ones, row-major (i, then j).
struct CellBox {
  std::int64_t i0 = 0, j0 = 0, w = 0, h = 0;
  std::int64_t Index(std::int64_t i, std::int64_t j) const { return (i - i0) * h + (j - j0); }
};

/// Most cells counted or accumulated densely over a box; beyond, the occupied cells are hashed.
constexpr std::int64_t kMaxDenseCells = std::int64_t{1} << 22;

/// Mean point per cell of a grid on the plane (basis) of the points, in (i, j) order, with the
/// cell doubled from `cell` until at most `max_samples` cells are occupied: the memory per
/// observation stays bounded whatever the plane's size. The points are projected once: the index
/// at cell c 2^k is floor(x / c) >> k exactly (dividing by a power of two commutes with rounding).
/// Cells are counted and summed over the box of the occupied ones (a bit, a slot per cell), which
/// shrinks fourfold per doubling; only a huge sparse box is hashed.
std::vector<Eigen::Vector3f> GridSamples(const std::vector<Eigen::Vector3f>& points,
                                         const PlaneBasis& basis, double cell, int max_samples) {
  std::vector<std::pair<std::int64_t, std::int64_t>> ij;
  std::vector<std::size_t> valid;
  ij.reserve(points.size());
  valid.reserve(points.size());
  for (std::size_t k = 0; k < points.size(); ++k) {
    if (!points[k].allFinite()) continue;
    const Eigen::Vector2d xy = basis.Project(points[k].cast<double>());
    ij.emplace_back(FloorIndex(xy.x(), cell), FloorIndex(xy.y(), cell));
    valid.push_back(k);
  }
  if (ij.empty()) return {};
  std::int64_t i0 = ij[0].first, i1 = i0, j0 = ij[0].second, j1 = j0;
  for (const auto& [i, j] : ij) {
    i0 = std::min(i0, i), i1 = std::max(i1, i), j0 = std::min(j0, j), j1 = std::max(j1, j);
  }
  const auto box_at = [&](int level) {
    CellBox box{i0 >> level, j0 >> level, 0, 0};
    box.w = (i1 >> level) - box.i0 + 1;
    box.h = (j1 >> level) - box.j0 + 1;
    return box;
  };
  const auto dense = [](const CellBox& box) { return box.w <= kMaxDenseCells / box.h; };
  // The first level with few enough occupied cells.
  int level = 0;
  for (;; ++level) {
    const CellBox box = box_at(level);
    std::size_t occupied = 0;
    if (dense(box)) {
      std::vector<std::uint64_t> bits(static_cast<std::size_t>((box.w * box.h + 63) / 64), 0);
      for (const auto& [i, j] : ij) {
        const auto c = static_cast<std::uint64_t>(box.Index(i >> level, j >> level));
        bits[c >> 6] |= std::uint64_t{1} << (c & 63);
      }
      for (const std::uint64_t word : bits) occupied += __builtin_popcountll(word);
    } else {
      absl::flat_hash_set<std::int64_t> cells;
      for (const auto& [i, j] : ij) cells.insert(CellKey(i >> level, j >> level));
      occupied = cells.size();
    }
    if (static_cast<int>(occupied) <= max_samples) break;
  }
  // Sums in input order per cell; cells numbered in (i, j) order.
  const CellBox box = box_at(level);
  std::vector<int> slot_of(ij.size());
  std::size_t cells = 0;
  if (dense(box)) {
    const auto at = [&](const std::pair<std::int64_t, std::int64_t>& c) {
      return static_cast<std::size_t>(box.Index(c.first >> level, c.second >> level));
    };
    std::vector<int> slot(static_cast<std::size_t>(box.w * box.h), -1);
    for (const auto& c : ij) slot[at(c)] = 0;
    for (int& s : slot) s = s < 0 ? -1 : static_cast<int>(cells++);
    for (std::size_t k = 0; k < ij.size(); ++k) slot_of[k] = slot[at(ij[k])];
  } else {
    std::vector<std::pair<std::int64_t, std::int64_t>> order;
    for (const auto& [i, j] : ij) order.emplace_back(i >> level, j >> level);
    std::sort(order.begin(), order.end());
    order.erase(std::unique(order.begin(), order.end()), order.end());
    absl::flat_hash_map<std::int64_t, int> slot;
    for (const auto& [i, j] : order) slot.emplace(CellKey(i, j), static_cast<int>(cells++));
    for (std::size_t k = 0; k < ij.size(); ++k) {
      slot_of[k] = slot.at(CellKey(ij[k].first >> level, ij[k].second >> level));
    }
  }
  std::vector<Eigen::Vector3d> sum(cells, Eigen::Vector3d::Zero());
  std::vector<int> count(cells, 0);
  for (std::size_t k = 0; k < ij.size(); ++k) {
    sum[slot_of[k]] += points[valid[k]].cast<double>();
    ++count[slot_of[k]];
  }
  std::vector<Eigen::Vector3f> samples;
  samples.reserve(cells);
  for (std::size_t c = 0; c < cells; ++c) samples.push_back((sum[c] / count[c]).cast<float>());
  return samples;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// PointStats

PointStats PointStats::FromMoments(const detection::PlaneMoments& moments) {
  PointStats s;
  s.count = moments.count();
  if (s.count == 0) return s;
  s.centroid = moments.Centroid();
  s.scatter = moments.Scatter();
  return s;
}

PointStats PointStats::Transformed(const Pose& T) const {
  PointStats s;
  s.count = count;
  const Eigen::Matrix3d R = T.linear();
  s.centroid = R * centroid + T.translation();
  s.scatter = R * scatter * R.transpose();
  s.scatter = 0.5 * (s.scatter + s.scatter.transpose());  // keep exactly symmetric
  return s;
}

void PointStats::Merge(const PointStats& other) {
  if (other.count == 0) return;
  if (count == 0) {
    *this = other;
    return;
  }
  const double k1 = static_cast<double>(count);
  const double k2 = static_cast<double>(other.count);
  const double k = k1 + k2;
  const Eigen::Vector3d delta = other.centroid - centroid;
  scatter += other.scatter + (k1 * k2 / k) * delta * delta.transpose();
  centroid += (k2 / k) * delta;
  count += other.count;
}

detection::PlaneFit PointStats::Fit(const Eigen::Vector3d& orientation) const {
  detection::PlaneFit fit;
  fit.centroid = centroid;
  if (count < 3) return fit;
  // The iterative solver rather than computeDirect: map planes are few, and its accuracy keeps a
  // rigidly moved map equal to the moved fit to ~1e-12.
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(scatter);
  fit.eigenvalues = solver.eigenvalues().cwiseMax(0.0);
  Eigen::Vector3d n = solver.eigenvectors().col(0).normalized();
  if (n.dot(orientation) < 0) n = -n;
  fit.normal = n;
  fit.d = n.dot(centroid);
  fit.mse = fit.eigenvalues(0) / static_cast<double>(count);
  fit.valid = n.allFinite();
  return fit;
}

// ---------------------------------------------------------------------------------------------
// PlaneMapConfig

std::vector<std::string> PlaneMapConfig::Validate() const {
  std::vector<std::string> problems;
  auto need = [&](bool ok, const std::string& what) {
    if (!ok) problems.push_back(what);
  };
  need(max_normal_angle_deg > 0 && max_normal_angle_deg < 90,
       "max_normal_angle_deg must be in (0, 90)");
  need(max_offset > 0, "max_offset must be > 0");
  need(max_offset_range_coeff >= 0, "max_offset_range_coeff must be >= 0");
  need(max_gap >= 0, "max_gap must be >= 0");
  need(min_touch_points >= 1, "min_touch_points must be >= 1");
  need(merge_max_normal_angle_deg > 0 && merge_max_normal_angle_deg < 90,
       "merge_max_normal_angle_deg must be in (0, 90)");
  need(merge_max_offset > 0, "merge_max_offset must be > 0");
  need(refit_merge_across_gaps_offset >= 0, "refit_merge_across_gaps_offset must be >= 0");
  need(min_observation_points >= 3, "min_observation_points must be >= 3");
  need(sample_cell_size > 0, "sample_cell_size must be > 0");
  need(max_samples_per_observation >= 16, "max_samples_per_observation must be >= 16");
  need(sample_pixel_stride >= 1, "sample_pixel_stride must be >= 1");
  for (const auto& p : polygon.Validate()) problems.push_back("polygon: " + p);
  return problems;
}

// ---------------------------------------------------------------------------------------------
// PlaneMap

PlaneMap::PlaneMap(const PlaneMapConfig& config)
    : config_(config), cos_merge_(std::cos(config.merge_max_normal_angle_deg * kDegToRad)) {
  const auto problems = config_.Validate();
  PLANESLAM_CHECK(problems.empty(), "invalid PlaneMapConfig: " << problems.front());
}

PlaneObservation PlaneMap::MakeObservation(std::int64_t keyframe_id, const detection::Plane& plane,
                                           const std::vector<Eigen::Vector3f>* points) const {
  PlaneObservation obs;
  obs.keyframe_id = keyframe_id;
  obs.detection_id = plane.id;
  obs.stats_sensor = PointStats::FromMoments(plane.moments);
  obs.normal_sensor = plane.normal.normalized();
  const detection::PlaneFit fit = obs.stats_sensor.Fit(obs.normal_sensor);
  const PlaneBasis basis = MakePlaneBasis(fit.normal, fit.d);

  if (points && !points->empty()) {
    // The outline's accuracy is set by the polygon cell: a coarser sample cell on a large plane
    // loses nothing there.
    obs.samples_sensor = GridSamples(*points, basis, config_.sample_cell_size,
                                     config_.max_samples_per_observation);
  }
  if (obs.samples_sensor.empty()) {
    // No points given: a point set spread uniformly over [-a, a] has variance a^2 / 3, so the
    // rectangle with half-sides sqrt(3 lambda / K) along the two in-plane principal axes has the
    // plane's second moments.
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(obs.stats_sensor.scatter);
    const double k = static_cast<double>(std::max<std::int64_t>(obs.stats_sensor.count, 1));
    const Eigen::Vector3d e1 = solver.eigenvectors().col(1);
    const Eigen::Vector3d e2 = solver.eigenvectors().col(2);
    const double a1 = std::sqrt(3.0 * std::max(solver.eigenvalues()(1), 0.0) / k);
    const double a2 = std::sqrt(3.0 * std::max(solver.eigenvalues()(2), 0.0) / k);
    double cell = config_.sample_cell_size;
    while ((2 * a1 / cell + 1) * (2 * a2 / cell + 1) > config_.max_samples_per_observation) {
      cell *= 2.0;
    }
    const int n1 = static_cast<int>(std::floor(a1 / cell));
    const int n2 = static_cast<int>(std::floor(a2 / cell));
    for (int i = -n1; i <= n1; ++i) {
      for (int j = -n2; j <= n2; ++j) {
        obs.samples_sensor.push_back(
            (obs.stats_sensor.centroid + (i * cell) * e1 + (j * cell) * e2).cast<float>());
      }
    }
  }
  return obs;
}

std::vector<Eigen::Vector3d> PlaneMap::WorldSamples(const MapPlane& plane) const {
  std::size_t count = 0;
  for (const auto& obs : plane.observations) count += obs.samples_sensor.size();
  std::vector<Eigen::Vector3d> out;
  out.reserve(count);
  for (const auto& obs : plane.observations) {
    const Pose& T = KeyframePose(obs.keyframe_id);
    for (const auto& s : obs.samples_sensor) out.push_back(T * s.cast<double>());
  }
  return out;
}

void PlaneMap::RefitPlane(MapPlane& plane) const {
  PointStats world;
  Eigen::Vector3d orientation = Eigen::Vector3d::Zero();
  plane.first_keyframe = std::numeric_limits<std::int64_t>::max();
  plane.last_keyframe = std::numeric_limits<std::int64_t>::min();
  for (const auto& obs : plane.observations) {
    const Pose& T = KeyframePose(obs.keyframe_id);
    world.Merge(obs.stats_sensor.Transformed(T));
    // Count-weighted sum of the observed normals: the sign reference of the fit, so the map normal
    // keeps pointing away from the sensors whatever the eigen solver's sign.
    orientation += static_cast<double>(obs.stats_sensor.count) * (T.linear() * obs.normal_sensor);
    plane.first_keyframe = std::min(plane.first_keyframe, obs.keyframe_id);
    plane.last_keyframe = std::max(plane.last_keyframe, obs.keyframe_id);
  }
  plane.stats_world = world;
  const detection::PlaneFit fit = world.Fit(orientation);
  plane.normal = fit.normal;
  plane.d = fit.d;
  plane.centroid = fit.centroid;
  plane.mse = fit.mse;
}

void PlaneMap::AddToExtent(Extent& extent, const std::vector<Eigen::Vector3d>& world_points) const {
  const double coarse = config_.max_gap + extent.cell;
  for (const auto& p : world_points) {
    const Eigen::Vector2d xy = extent.basis.Project(p);
    // A point in a known fine cell adds nothing: its coarse cell is known, and the box holds a
    // point of its cell (what CountTouching's rejection by the box needs).
    const std::int64_t i = FloorIndex(xy.x(), extent.cell), j = FloorIndex(xy.y(), extent.cell);
    if (!extent.fine.insert(CellKey(i, j)).second) continue;
    extent.coarse.insert(CellKey(FloorIndex(xy.x(), coarse), FloorIndex(xy.y(), coarse)));
    extent.box.extend(xy);
  }
}

void PlaneMap::InvalidateExtent(const MapPlane& plane) { extents_[IndexOf(plane.id)] = Extent(); }

PlaneMap::Extent& PlaneMap::ExtentAt(std::size_t i) {
  Extent& extent = extents_[i];
  if (extent.stale) {
    extent.basis = MakePlaneBasis(planes_[i].normal, planes_[i].d);
    extent.cell = config_.sample_cell_size;
    const std::vector<Eigen::Vector3d> samples = WorldSamples(planes_[i]);
    extent.fine.reserve(samples.size());  // most samples have a cell of their own
    AddToExtent(extent, samples);
    extent.stale = false;
  }
  return extent;
}

int PlaneMap::CountTouching(const Extent& extent, const std::vector<Eigen::Vector3d>& world_points,
                            int enough) const {
  // A point touches the extent when an occupied cell's centre lies within max_gap plus half a cell
  // diagonal of it. The coarse cells have that radius as size, so a 3x3 coarse neighbourhood holds
  // every candidate and most points are rejected with 9 hash look-ups.
  const double radius = config_.max_gap + extent.cell * M_SQRT1_2;
  const double coarse = config_.max_gap + extent.cell;
  const int r = static_cast<int>(std::ceil(radius / extent.cell));
  // Every occupied cell's centre lies within a cell of the box (which holds a point of each).
  const double reach = radius + extent.cell;
  if (extent.box.isEmpty()) return 0;
  int touching = 0;
  for (const auto& p : world_points) {
    const Eigen::Vector2d xy = extent.basis.Project(p);
    if (extent.box.exteriorDistance(xy) > reach) continue;
    const std::int64_t ci = FloorIndex(xy.x(), coarse);
    const std::int64_t cj = FloorIndex(xy.y(), coarse);
    bool near_coarse = false;
    for (int di = -1; di <= 1 && !near_coarse; ++di) {
      for (int dj = -1; dj <= 1 && !near_coarse; ++dj) {
        near_coarse = extent.coarse.count(CellKey(ci + di, cj + dj)) != 0;
      }
    }
    if (!near_coarse) continue;
    const std::int64_t fi = FloorIndex(xy.x(), extent.cell);
    const std::int64_t fj = FloorIndex(xy.y(), extent.cell);
    bool near = false;
    for (int di = -r; di <= r && !near; ++di) {
      for (int dj = -r; dj <= r && !near; ++dj) {
        const Eigen::Vector2d centre((fi + di + 0.5) * extent.cell, (fj + dj + 0.5) * extent.cell);
        if ((centre - xy).norm() > radius) continue;
        near = extent.fine.count(CellKey(fi + di, fj + dj)) != 0;
      }
    }
    if (near && ++touching >= enough) return touching;
  }
  return touching;
}

bool PlaneMap::Coincide(const MapPlane& a, const MapPlane& b, double across_gaps_offset) {
  if (a.normal.dot(b.normal) < cos_merge_) {
    return false;
  }
  const double offset =
      std::max(std::abs(a.normal.dot(b.centroid) - a.d), std::abs(b.normal.dot(a.centroid) - b.d));
  if (offset > config_.merge_max_offset) return false;
  if (offset <= across_gaps_offset) return true;  // one surface whatever the gap
  // Touching: b's occupied cells (as world points) near a's extent.
  const Extent& eb = ExtentAt(IndexOf(b.id));
  std::vector<Eigen::Vector3d> cells;
  cells.reserve(eb.fine.size());
  for (const std::int64_t key : eb.fine) {
    const std::int64_t i = CellI(key), j = CellJ(key);
    cells.push_back(eb.basis.Unproject(Eigen::Vector2d((static_cast<double>(i) + 0.5) * eb.cell,
                                                       (static_cast<double>(j) + 0.5) * eb.cell)));
  }
  // The order of the cells (the hash set's) does not matter: whether `need` of them touch does
  // not depend on which are counted first.
  const int need = std::min<int>(config_.min_touch_points, static_cast<int>(cells.size()));
  return need > 0 && CountTouching(ExtentAt(IndexOf(a.id)), cells, need) >= need;
}

std::size_t PlaneMap::IndexOf(int id) const {
  for (std::size_t i = 0; i < planes_.size(); ++i) {
    if (planes_[i].id == id) return i;
  }
  PLANESLAM_CHECK(false, "no map plane with id " << id);
  return 0;
}

void PlaneMap::MergeInto(std::size_t i, std::size_t j) {
  PLANESLAM_CHECK(i != j && i < planes_.size() && j < planes_.size(), "bad merge indices");
  MapPlane& keep = planes_[i];
  MapPlane& gone = planes_[j];
  for (auto& obs : gone.observations) keep.observations.push_back(std::move(obs));
  merged_into_[gone.id] = keep.id;
  const int keep_id = keep.id;
  planes_.erase(planes_.begin() + static_cast<std::ptrdiff_t>(j));
  extents_.erase(extents_.begin() + static_cast<std::ptrdiff_t>(j));
  MapPlane& merged = planes_[IndexOf(keep_id)];
  RefitPlane(merged);
  InvalidateExtent(merged);
}

int PlaneMap::Remove(const std::unordered_set<int>& ids) {
  int removed = 0;
  for (std::size_t i = planes_.size(); i-- > 0;) {
    if (ids.count(planes_[i].id) == 0) continue;
    planes_.erase(planes_.begin() + static_cast<std::ptrdiff_t>(i));
    extents_.erase(extents_.begin() + static_cast<std::ptrdiff_t>(i));
    ++removed;
  }
  return removed;
}

int PlaneMap::ResolveId(int id) const {
  int current = id;
  for (auto it = merged_into_.find(current); it != merged_into_.end();
       it = merged_into_.find(current)) {
    current = it->second;
  }
  for (const auto& p : planes_) {
    if (p.id == current) return current;
  }
  return -1;
}

const MapPlane* PlaneMap::Find(int id) const {
  const int current = ResolveId(id);
  if (current < 0) return nullptr;
  return &planes_[IndexOf(current)];
}

const Pose& PlaneMap::KeyframePose(std::int64_t keyframe_id) const {
  const auto it = keyframe_poses_.find(keyframe_id);
  PLANESLAM_CHECK(it != keyframe_poses_.end(), "unknown keyframe " << keyframe_id);
  return it->second;
}

FrameAssociation PlaneMap::AddObservations(
    std::int64_t keyframe_id, const Pose& T_world_sensor,
    const std::vector<detection::Plane>& planes,
    const std::vector<std::vector<Eigen::Vector3f>>& plane_points) {
  PLANESLAM_CHECK(plane_points.empty() || plane_points.size() == planes.size(),
                  "plane_points must be empty or have one entry per plane");
  PLANESLAM_CHECK(T_world_sensor.matrix().allFinite(), "pose not finite");
  if (const auto it = keyframe_poses_.find(keyframe_id); it != keyframe_poses_.end()) {
    PLANESLAM_CHECK(it->second.isApprox(T_world_sensor, 1e-12),
                    "keyframe " << keyframe_id << " added again with another pose (use Refit)");
  } else {
    keyframe_poses_[keyframe_id] = T_world_sensor;
  }
  const Pose& T = keyframe_poses_.at(keyframe_id);
  const double cos_assoc = std::cos(config_.max_normal_angle_deg * kDegToRad);
  const double cos_rebuild = std::cos(kExtentRebuildAngleDeg * kDegToRad);

  FrameAssociation result;
  result.map_ids.assign(planes.size(), -1);
  for (std::size_t k = 0; k < planes.size(); ++k) {
    const detection::Plane& plane = planes[k];
    if (plane.moments.count() < config_.min_observation_points) continue;
    if (!plane.normal.allFinite() || plane.normal.norm() < 0.5) continue;
    PlaneObservation obs =
        MakeObservation(keyframe_id, plane, plane_points.empty() ? nullptr : &plane_points[k]);
    const PointStats world = obs.stats_sensor.Transformed(T);
    const detection::PlaneFit fit = world.Fit(T.linear() * obs.normal_sensor);
    if (!fit.valid) continue;
    std::vector<Eigen::Vector3d> samples;
    samples.reserve(obs.samples_sensor.size());
    for (const auto& s : obs.samples_sensor) samples.push_back(T * s.cast<double>());

    const double range2 = obs.stats_sensor.centroid.squaredNorm();
    const double offset_gate = config_.max_offset + config_.max_offset_range_coeff * range2;
    // Candidates, best (smallest offset) first.
    std::vector<std::pair<double, int>> candidates;
    const int need = std::min<int>(config_.min_touch_points, static_cast<int>(samples.size()));
    for (std::size_t i = 0; i < planes_.size(); ++i) {
      const MapPlane& m = planes_[i];
      if (m.normal.dot(fit.normal) < cos_assoc) continue;
      const double offset = std::abs(m.normal.dot(fit.centroid) - m.d);
      if (offset > offset_gate) continue;
      if (need == 0 || CountTouching(ExtentAt(i), samples, need) < need) continue;
      candidates.emplace_back(offset, m.id);
    }
    std::sort(candidates.begin(), candidates.end());

    if (candidates.empty()) {
      MapPlane m;
      m.id = next_id_++;
      m.observations.push_back(std::move(obs));
      RefitPlane(m);
      planes_.push_back(std::move(m));
      extents_.emplace_back();
      InvalidateExtent(planes_.back());
      result.map_ids[k] = planes_.back().id;
      ++result.created;
      continue;
    }

    const int best_id = candidates.front().second;
    {
      MapPlane& m = planes_[IndexOf(best_id)];
      Extent& e = ExtentAt(IndexOf(best_id));
      // Keep only the samples that extend the plane's known extent: the samples of a plane then
      // grow with its area, not with the number of keyframes that saw it (a floor seen by 1000
      // keyframes would otherwise hold 1000 copies of itself). After a Refit, the overlap they
      // duplicated stays covered by the earlier observations (moved by their own corrections).
      std::vector<Eigen::Vector3f> novel;
      std::vector<Eigen::Vector3d> novel_world;
      for (std::size_t s = 0; s < samples.size(); ++s) {
        const Eigen::Vector2d xy = e.basis.Project(samples[s]);
        if (e.fine.count(CellKey(FloorIndex(xy.x(), e.cell), FloorIndex(xy.y(), e.cell))) == 0) {
          novel.push_back(obs.samples_sensor[s]);
          novel_world.push_back(samples[s]);
        }
      }
      obs.samples_sensor = std::move(novel);
      samples = std::move(novel_world);
      m.observations.push_back(std::move(obs));
      // Incremental update of the fit (Refit recomputes from scratch with the same formulas).
      m.stats_world.Merge(world);
      const detection::PlaneFit mf = m.stats_world.Fit(m.normal);
      m.normal = mf.normal;
      m.d = mf.d;
      m.centroid = mf.centroid;
      m.mse = mf.mse;
      m.first_keyframe = std::min(m.first_keyframe, keyframe_id);
      m.last_keyframe = std::max(m.last_keyframe, keyframe_id);
      if (m.normal.dot(e.basis.normal) < cos_rebuild) {
        InvalidateExtent(m);
      } else {
        AddToExtent(e, samples);
      }
      ++result.associated;
    }
    // The observation touches every candidate and lies on each: the candidates are one surface,
    // provided the map planes also agree with each other within the (stricter) merge thresholds.
    int survivor = best_id;
    for (std::size_t c = 1; c < candidates.size(); ++c) {
      const int other = candidates[c].second;
      const MapPlane& a = planes_[IndexOf(survivor)];
      const MapPlane& b = planes_[IndexOf(other)];
      if (a.normal.dot(b.normal) < cos_merge_) continue;
      if (std::abs(a.normal.dot(b.centroid) - a.d) > config_.merge_max_offset ||
          std::abs(b.normal.dot(a.centroid) - b.d) > config_.merge_max_offset) {
        continue;
      }
      const int keep = std::min(survivor, other);
      const int drop = std::max(survivor, other);
      MergeInto(IndexOf(keep), IndexOf(drop));
      survivor = keep;
      ++result.merged;
    }
    result.map_ids[k] = survivor;
  }
  // Ids handed out earlier in this frame may have been merged away since.
  for (int& id : result.map_ids) {
    if (id > 0) id = ResolveId(id);
  }
  return result;
}

FrameAssociation PlaneMap::AddFrame(std::int64_t keyframe_id, const Pose& T_world_sensor,
                                    const detection::Segmentation& segmentation,
                                    const datasets::OrganizedCloud& cloud) {
  PLANESLAM_CHECK(segmentation.labels.size() == cloud.size(),
                  "label image (" << segmentation.labels.size() << ") and cloud (" << cloud.size()
                                  << ") differ in size");
  std::unordered_map<int, std::size_t> index_of_id;
  for (std::size_t i = 0; i < segmentation.planes.size(); ++i) {
    index_of_id[segmentation.planes[i].id] = i;
  }
  // Neighbouring pixels mostly share a label: the last one's plane is tried first.
  int last_label = 0;
  std::vector<Eigen::Vector3f>* last_points = nullptr;
  std::vector<std::vector<Eigen::Vector3f>> points(segmentation.planes.size());
  const int stride =
      cloud.model == datasets::SensorModel::kPinhole ? config_.sample_pixel_stride : 1;
  for (int row = 0; row < cloud.height; row += stride) {
    for (int col = 0; col < cloud.width; col += stride) {
      const std::size_t p = static_cast<std::size_t>(row) * cloud.width + col;
      const int label = segmentation.labels[p];
      if (label < 1 || !cloud.IsValid(p)) continue;
      if (label != last_label) {
        const auto it = index_of_id.find(label);
        last_label = label;
        last_points = it != index_of_id.end() ? &points[it->second] : nullptr;
      }
      if (last_points) last_points->push_back(cloud.points[p]);
    }
  }
  return AddObservations(keyframe_id, T_world_sensor, segmentation.planes, points);
}

int PlaneMap::Refit(const std::unordered_map<std::int64_t, Pose>& T_world_keyframe) {
  // Only the planes seen from a keyframe that moved are re-fitted and compared again: after a
  // windowed optimisation that is the window's planes, so the cost follows the window.
  std::unordered_set<std::int64_t> moved;
  for (const auto& [id, pose] : T_world_keyframe) {
    PLANESLAM_CHECK(pose.matrix().allFinite(), "pose of keyframe " << id << " not finite");
    const auto it = keyframe_poses_.find(id);
    if (it == keyframe_poses_.end() || it->second.matrix() == pose.matrix()) continue;
    it->second = pose;
    moved.insert(id);
  }
  std::unordered_set<int> changed;
  for (auto& plane : planes_) {
    const bool seen_moving =
        std::any_of(plane.observations.begin(), plane.observations.end(),
                    [&](const PlaneObservation& obs) { return moved.count(obs.keyframe_id) != 0; });
    if (!seen_moving) continue;
    RefitPlane(plane);
    InvalidateExtent(plane);
    changed.insert(plane.id);
  }
  return MergeCoincident(config_.refit_merge_across_gaps_offset, &changed);
}

int PlaneMap::SplitContradicted() {
  // An observation contradicts its plane when, at the current poses, it would no longer pass the
  // association gates (normal angle, centroid offset with the range term). The contradicting
  // observations of a plane leave it together as a new plane: the merge that joined them is
  // undone, and both parts are re-fitted.
  const double cos_gate = std::cos(config_.max_normal_angle_deg * kDegToRad);
  int splits = 0;
  const std::size_t existing = planes_.size();
  for (std::size_t i = 0; i < existing; ++i) {
    std::vector<PlaneObservation> keep, leave;
    for (PlaneObservation& obs : planes_[i].observations) {
      const Pose& T = KeyframePose(obs.keyframe_id);
      const double range = obs.stats_sensor.centroid.norm();
      const double offset =
          std::abs(planes_[i].normal.dot(T * obs.stats_sensor.centroid) - planes_[i].d);
      const bool agrees =
          planes_[i].normal.dot(T.linear() * obs.normal_sensor) >= cos_gate &&
          offset <= config_.max_offset + config_.max_offset_range_coeff * range * range;
      (agrees ? keep : leave).push_back(std::move(obs));
    }
    if (leave.empty() || keep.empty()) {
      auto& observations = planes_[i].observations;
      observations = keep.empty() ? std::move(leave) : std::move(keep);
      continue;
    }
    planes_[i].observations = std::move(keep);
    RefitPlane(planes_[i]);
    InvalidateExtent(planes_[i]);
    MapPlane split;
    split.id = next_id_++;
    split.observations = std::move(leave);
    RefitPlane(split);
    planes_.push_back(std::move(split));
    extents_.emplace_back();
    InvalidateExtent(planes_.back());
    ++splits;
  }
  return splits;
}

int PlaneMap::MergeCoincidentPlanes(double across_gaps_offset) {
  return MergeCoincident(across_gaps_offset, nullptr);
}

int PlaneMap::MergeCoincident(double across_gaps_offset, std::unordered_set<int>* changed) {
  int merges = 0;
  bool merged = true;
  while (merged) {
    merged = false;
    for (std::size_t i = 0; i < planes_.size() && !merged; ++i) {
      for (std::size_t j = i + 1; j < planes_.size() && !merged; ++j) {
        if (changed && !changed->count(planes_[i].id) && !changed->count(planes_[j].id)) continue;
        if (Coincide(planes_[i], planes_[j], across_gaps_offset) ||
            Coincide(planes_[j], planes_[i], across_gaps_offset)) {
          const bool i_first = planes_[i].id < planes_[j].id;
          if (changed) changed->insert(i_first ? planes_[i].id : planes_[j].id);
          MergeInto(i_first ? i : j, i_first ? j : i);
          ++merges;
          merged = true;
        }
      }
    }
  }
  return merges;
}

MapPlaneOutline PlaneMap::Outline(const MapPlane& plane) const {
  MapPlaneOutline out;
  out.id = plane.id;
  out.basis = MakePlaneBasis(plane.normal, plane.d);
  std::vector<Eigen::Vector2d> xy;
  for (const auto& p : WorldSamples(plane)) xy.push_back(out.basis.Project(p));
  out.region = ConcaveHull(xy, config_.polygon);
  {
    const double cell =
        out.region.cell_size > 0 ? out.region.cell_size : 2.0 * config_.sample_cell_size;
    std::unordered_set<std::int64_t> occupied;
    for (const auto& p : xy)
      occupied.insert(CellKey(FloorIndex(p.x(), cell), FloorIndex(p.y(), cell)));
    std::int64_t boundary_edges = 0;
    for (const std::int64_t key : occupied) {
      const std::int64_t i = CellI(key), j = CellJ(key);
      boundary_edges +=
          (occupied.count(CellKey(i + 1, j)) == 0) + (occupied.count(CellKey(i - 1, j)) == 0) +
          (occupied.count(CellKey(i, j + 1)) == 0) + (occupied.count(CellKey(i, j - 1)) == 0);
    }
    // Boundary bias: the cell holding the outermost sample reaches cell/2 beyond it on average, and
    // that sample (a mean over a sample cell cut by the true edge) lies sample_cell/4 inside the
    // edge on average; so each boundary cell edge overshoots by cell/2 - sample_cell/4.
    const double overshoot = 0.5 * cell - 0.25 * config_.sample_cell_size;
    out.observed_area = static_cast<double>(occupied.size()) * cell * cell -
                        static_cast<double>(boundary_edges) * cell * overshoot;
    out.observed_area = std::max(out.observed_area, 0.0);
  }
  for (const Polygon2& part : out.region.parts) {
    auto& world = out.part_vertices.emplace_back();
    for (const auto& v : part.vertices) world.push_back(out.basis.Unproject(v));
    out.part_triangles.push_back(TriangulatePolygon(part.vertices));
  }
  return out;
}

std::vector<MapPlaneOutline> PlaneMap::Outlines() const {
  std::vector<MapPlaneOutline> out;
  out.reserve(planes_.size());
  for (const auto& p : planes_) out.push_back(Outline(p));
  return out;
}

}  // namespace planeslam::mapping
