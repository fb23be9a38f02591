#include "planeslam/registration/local_map.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

#include "prior_step.hpp"

namespace planeslam::registration {

using internal::Chi2Quantile999;
using internal::IsTranslation;

std::vector<std::string> LocalMapConfig::Validate() const {
  std::vector<std::string> p;
  if (!(voxel_size >= 0)) p.push_back("voxel_size must be >= 0 (0 = from the first scan)");
  if (max_points_per_voxel < 1) p.push_back("max_points_per_voxel must be >= 1");
  if (max_iterations < 1) p.push_back("max_iterations must be >= 1");
  if (!(max_translation_sigma > 0)) p.push_back("max_translation_sigma must be > 0");
  if (!(max_rotation_sigma > 0)) p.push_back("max_rotation_sigma must be > 0");
  if (min_support < 0) p.push_back("min_support must be >= 0");
  return p;
}

std::vector<ScanPoint> StructurePoints(const datasets::OrganizedCloud& cloud,
                                       const std::vector<std::int32_t>* labels) {
  const bool use_labels = labels != nullptr && labels->size() == cloud.points.size();
  std::vector<ScanPoint> out;
  out.reserve(cloud.points.size() / 4);
  for (std::size_t i = 0; i < cloud.points.size(); ++i) {
    const Eigen::Vector3f& p = cloud.points[i];
    if (!p.allFinite()) continue;
    if (use_labels && (*labels)[i] >= 1) continue;
    const int row = static_cast<int>(i / static_cast<std::size_t>(cloud.width));
    out.push_back({p.cast<double>(), row, static_cast<int>(i) - row * cloud.width});
  }
  return out;
}

namespace {

/// The voxel of edge `voxel` holding p; `inverse` is 1 / voxel.
Eigen::Vector3i VoxelOf(const Eigen::Vector3d& p, double voxel, double inverse) {
  return {FloorDivToInt(p.x(), voxel, inverse), FloorDivToInt(p.y(), voxel, inverse),
          FloorDivToInt(p.z(), voxel, inverse)};
}

/// The unit eigenvector of the symmetric `C` for its simple eigenvalue `lambda`: the largest
/// cross product of two rows of C - lambda I (each row is orthogonal to it).
Eigen::Vector3d EigenvectorOf(const Eigen::Matrix3d& C, double lambda) {
  const Eigen::Matrix3d M = C - lambda * Eigen::Matrix3d::Identity();
  const Eigen::Vector3d c01 = M.row(0).transpose().cross(M.row(1).transpose());
  const Eigen::Vector3d c02 = M.row(0).transpose().cross(M.row(2).transpose());
  const Eigen::Vector3d c12 = M.row(1).transpose().cross(M.row(2).transpose());
  const double n01 = c01.squaredNorm(), n02 = c02.squaredNorm(), n12 = c12.squaredNorm();
  if (n01 >= n02 && n01 >= n12) return c01 / std::sqrt(n01);
  return n02 >= n12 ? Eigen::Vector3d(c02 / std::sqrt(n02)) : Eigen::Vector3d(c12 / std::sqrt(n12));
}

/// The projector onto the axes along which the neighbourhood of a point is thin: a variance
/// below a ninth of the largest (a third in sigma) marks a constrained axis. A surface gives its
/// normal, an edge or a pole the plane across it. A blob or too few neighbours give zero: such a
/// point has no direction it pins down, and paired point to point with its nearest neighbour it
/// would only hold the estimate where it starts. An edge must span two rows and two columns of
/// the grid: a sparse scan (a LiDAR ring on the road, a far floor's pixel row) looks like a line
/// that is only the sampling, and moves with the sensor.
///
/// `scatter` is the neighbours' scatter about their mean. Its smallest eigenvalue comes from
/// Newton's method on the characteristic cubic started at 0, below it, where the cubic is
/// increasing and concave, so the iterates rise monotonically onto it (quadratically when it is
/// simple, as for a surface; for an edge, whose two small ones nearly coincide, a dozen steps
/// leave it well within the ninth of the largest that decides); the other two solve the
/// quadratic left. A surface needs the eigenvector of the smallest, an edge the plane across the
/// largest's: each is simple there, being under a ninth of the largest or the largest.
Eigen::Matrix3d NeighbourhoodShape(const Eigen::Matrix3d& scatter, bool rows_and_cols) {
  const Eigen::Matrix3d& C = scatter;
  const double c2 = C.trace();
  const double c1 = C(0, 0) * C(1, 1) - C(0, 1) * C(0, 1) + C(0, 0) * C(2, 2) -
                    C(0, 2) * C(0, 2) + C(1, 1) * C(2, 2) - C(1, 2) * C(1, 2);
  const double c0 = C.determinant();
  if (!(c2 > 0)) return Eigen::Matrix3d::Zero();
  double l0 = 0.0;
  for (int it = 0; it < 12; ++it) {
    const double p = ((l0 - c2) * l0 + c1) * l0 - c0;  // <= 0 below the root
    const double dp = (3.0 * l0 - 2.0 * c2) * l0 + c1;
    if (!(p < 0 && dp > 0)) break;
    const double step = -p / dp;
    l0 += step;
    if (step <= 1e-12 * c2) break;
  }
  const double half = 0.5 * (c2 - l0);  // the mean of the two others
  const double product = c1 - l0 * (c2 - l0);
  const double root = std::sqrt(std::max(half * half - product, 0.0));
  const double l1 = half - root, l2 = half + root;
  if (!(l2 > 0)) return Eigen::Matrix3d::Zero();
  const double thin = l2 / 9.0;
  if (!(l1 < thin)) {
    if (!(l0 < thin)) return Eigen::Matrix3d::Zero();  // a blob
    const Eigen::Vector3d n = EigenvectorOf(C, l0);
    return n * n.transpose();  // a surface: its normal
  }
  if (!rows_and_cols) return Eigen::Matrix3d::Zero();  // a line that is only the sampling
  const Eigen::Vector3d a = EigenvectorOf(C, l2);
  return Eigen::Matrix3d::Identity() - a * a.transpose();  // an edge: the plane across it
}

/// A candidate neighbour, copied out of the input so that a voxel's scan reads one array.
struct Candidate {
  Eigen::Vector3d position;
  int row = 0;
  int col = 0;
};

/// ShapePoints' buffers, kept by each thread.
struct ShapeScratch {
  std::vector<int> voxel_of, start, order;
  std::vector<Eigen::Vector3i> keys;
  std::vector<Candidate> candidates;
  std::vector<int> near;
  std::vector<Eigen::Matrix3d> shape_of;
};

/// The shape of the neighbours of `point` among `candidates` (those within sqrt(r2); the point
/// is one of them): their offsets from the point are summed in one pass, and the scatter about
/// their mean is outer - sum sum^T / count (offsets within the radius keep the digits that
/// absolute positions of a distant scan would lose). The neighbours are picked first without a
/// branch (about one candidate in five is one, at random), then summed in candidate order.
Eigen::Matrix3d ShapeAmong(const std::vector<Candidate>& candidates, const ScanPoint& point,
                           double r2, std::vector<int>* near) {
  const Eigen::Vector3d& p = point.position;
  near->resize(candidates.size());
  int* picked = near->data();
  int count = 0;
  for (std::size_t k = 0; k < candidates.size(); ++k) {
    picked[count] = static_cast<int>(k);
    count += (candidates[k].position - p).squaredNorm() > r2 ? 0 : 1;
  }
  if (count < 5) return Eigen::Matrix3d::Zero();
  bool rows = false, cols = false;  // neighbours off the point's row, column
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  double xx = 0, xy = 0, xz = 0, yy = 0, yz = 0, zz = 0;
  for (int j = 0; j < count; ++j) {
    const Candidate& q = candidates[static_cast<std::size_t>(picked[j])];
    const Eigen::Vector3d d = q.position - p;
    rows = rows || q.row != point.row;
    cols = cols || q.col != point.col;
    sum += d;
    xx += d.x() * d.x();
    xy += d.x() * d.y();
    xz += d.x() * d.z();
    yy += d.y() * d.y();
    yz += d.y() * d.z();
    zz += d.z() * d.z();
  }
  Eigen::Matrix3d scatter;
  scatter << xx, xy, xz, xy, yy, yz, xz, yz, zz;
  scatter.noalias() -= sum * sum.transpose() / static_cast<double>(count);
  return NeighbourhoodShape(scatter, rows && cols);
}

}  // namespace

std::vector<ShapedPoint> ShapePoints(const std::vector<ScanPoint>& points, double radius) {
  // Buffers kept by the thread across scans: allocated afresh they would be mapped and faulted
  // in page by page on every scan.
  thread_local ShapeScratch scratch;
  std::vector<int>& voxel_of = scratch.voxel_of;
  std::vector<int>& start = scratch.start;
  std::vector<int>& order = scratch.order;
  std::vector<Eigen::Vector3i>& keys = scratch.keys;  // per voxel
  std::vector<Candidate>& candidates = scratch.candidates;
  std::vector<Eigen::Matrix3d>& shape_of = scratch.shape_of;
  // The points bucketed by voxel of edge `radius` (counting sort, input order kept in a bucket),
  // and a bitmap of occupied voxels by hash: most of a voxel's 26 neighbours are empty, and the
  // bitmap, small enough to stay in the first-level cache, turns them away without a probe.
  VoxelIndex index(points.size() / 2);
  const double inverse = 1.0 / radius;
  VoxelBitmap<16> occupied;  // 8 KiB
  voxel_of.resize(points.size());
  start.clear();
  keys.clear();
  for (std::size_t i = 0; i < points.size(); ++i) {
    bool inserted = false;
    const Eigen::Vector3i key = VoxelOf(points[i].position, radius, inverse);
    voxel_of[i] = index.Insert(key, &inserted);
    if (inserted) {
      start.push_back(0);
      keys.push_back(key);
      occupied.Set(key);
    }
    ++start[static_cast<std::size_t>(voxel_of[i])];
  }
  int sum = 0;
  for (int& s : start) {
    const int count = s;
    s = sum;
    sum += count;
  }
  start.push_back(sum);
  order.resize(points.size());
  {
    std::vector<int> fill(start.begin(), start.end() - 1);
    for (std::size_t i = 0; i < points.size(); ++i) {
      order[static_cast<std::size_t>(fill[static_cast<std::size_t>(voxel_of[i])]++)] =
          static_cast<int>(i);
    }
  }
  // Voxel by voxel: the points of the 27 voxels around one are gathered once for all of its
  // points. The neighbours of a point keep the order of the candidates (voxel offsets, then input
  // order), so each shape is the same whatever order the points are taken in.
  shape_of.resize(points.size());
  const double r2 = radius * radius;
  std::size_t num_shaped = 0;
  for (std::size_t v = 0; v < keys.size(); ++v) {
    const Eigen::Vector3i& key = keys[v];
    candidates.clear();
    for (int dx = -1; dx <= 1; ++dx) {
      for (int dy = -1; dy <= 1; ++dy) {
        for (int dz = -1; dz <= 1; ++dz) {
          const Eigen::Vector3i neighbour = key + Eigen::Vector3i(dx, dy, dz);
          if (!occupied.MaybeSet(neighbour)) continue;
          const int u = index.Find(neighbour);
          if (u < 0) continue;
          for (int k = start[static_cast<std::size_t>(u)]; k < start[static_cast<std::size_t>(u) + 1];
               ++k) {
            const ScanPoint& q = points[static_cast<std::size_t>(order[static_cast<std::size_t>(k)])];
            candidates.push_back({q.position, q.row, q.col});
          }
        }
      }
    }
    for (int k = start[v]; k < start[v + 1]; ++k) {
      const std::size_t i = static_cast<std::size_t>(order[static_cast<std::size_t>(k)]);
      shape_of[i] = ShapeAmong(candidates, points[i], r2, &scratch.near);
      num_shaped += shape_of[i].isZero() ? 0 : 1;
    }
  }
  std::vector<ShapedPoint> shaped;
  shaped.reserve(num_shaped);
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (!shape_of[i].isZero()) shaped.push_back({points[i].position, shape_of[i]});
  }
  return shaped;
}

namespace {

/// The first point of each voxel, in input order (ScanPoint and ShapedPoint alike).
template <typename Point>
std::vector<Point> FirstPerVoxel(const std::vector<Point>& points, double voxel) {
  if (!(voxel > 0)) return points;
  VoxelIndex seen(points.size() / 2);
  const double inverse = 1.0 / voxel;
  std::vector<Point> out;
  for (const auto& p : points) {
    bool inserted = false;
    seen.Insert(VoxelOf(p.position, voxel, inverse), &inserted);
    if (inserted) out.push_back(p);
  }
  return out;
}

}  // namespace

std::vector<ScanPoint> VoxelDownsample(const std::vector<ScanPoint>& points, double voxel) {
  return FirstPerVoxel(points, voxel);
}

std::vector<ShapedPoint> ThinShapedPoints(const std::vector<ShapedPoint>& points, double voxel) {
  return FirstPerVoxel(points, voxel);
}

std::vector<ShapedPoint> ScanStructure(const datasets::OrganizedCloud& cloud,
                                       const std::vector<std::int32_t>* labels, double voxel) {
  // VoxelDownsample(StructurePoints(cloud, labels), voxel / 2) in one pass over the cloud.
  const bool use_labels = labels != nullptr && labels->size() == cloud.points.size();
  const double thin = 0.5 * voxel;
  const double inverse = 1.0 / thin;
  VoxelIndex seen(cloud.points.size() / 16);
  std::vector<ScanPoint> thinned;
  thinned.reserve(cloud.points.size() / 8);
  const std::size_t width = static_cast<std::size_t>(cloud.width);
  for (int row = 0; row < cloud.height; ++row) {
    // Neighbouring pixels of a row mostly share a voxel: the last one met skips the hash.
    Eigen::Vector3i last(std::numeric_limits<int>::min(), 0, 0);
    for (int col = 0; col < cloud.width; ++col) {
      const std::size_t i = static_cast<std::size_t>(row) * width + static_cast<std::size_t>(col);
      const Eigen::Vector3f& p = cloud.points[i];
      if (!p.allFinite() || (use_labels && (*labels)[i] >= 1)) continue;
      const Eigen::Vector3d position = p.cast<double>();
      const Eigen::Vector3i key = VoxelOf(position, thin, inverse);
      if (key == last) continue;
      last = key;
      bool inserted = false;
      seen.Insert(key, &inserted);
      if (inserted) thinned.push_back({position, row, col});
    }
  }
  return ShapePoints(thinned, voxel);
}

namespace {

/// The unit axis of a rank-1 projector a a^T: its column of largest diagonal, normalised.
Eigen::Vector3d ProjectorAxis(const Eigen::Matrix3d& P) {
  int j = 0;
  P.diagonal().maxCoeff(&j);
  const double norm = P.col(j).norm();
  return norm > 0 ? Eigen::Vector3d(P.col(j) / norm) : Eigen::Vector3d::UnitZ();
}

}  // namespace

std::vector<CompactShapedPoint> CompactShapedPoints(const std::vector<ShapedPoint>& points) {
  std::vector<CompactShapedPoint> out;
  out.reserve(points.size());
  for (const ShapedPoint& p : points) {
    CompactShapedPoint c;
    c.position = p.position.cast<float>();
    c.edge = p.shape.trace() > 1.5;
    const Eigen::Matrix3d rank1 = c.edge ? Eigen::Matrix3d(Eigen::Matrix3d::Identity() - p.shape)
                                         : p.shape;
    c.axis = ProjectorAxis(rank1).cast<float>();
    out.push_back(c);
  }
  return out;
}

std::vector<ShapedPoint> ExpandShapedPoints(const std::vector<CompactShapedPoint>& points) {
  std::vector<ShapedPoint> out;
  out.reserve(points.size());
  for (const CompactShapedPoint& c : points) {
    const Eigen::Vector3d a = c.axis.cast<double>().normalized();
    const Eigen::Matrix3d rank1 = a * a.transpose();
    out.push_back({c.position.cast<double>(),
                   c.edge ? Eigen::Matrix3d(Eigen::Matrix3d::Identity() - rank1) : rank1});
  }
  return out;
}

double ScanReach(const datasets::OrganizedCloud& cloud) {
  std::vector<double> ranges;
  ranges.reserve(cloud.points.size() / 4 + 1);
  for (std::size_t i = 0; i < cloud.points.size(); i += 4) {  // a sample is enough
    if (cloud.points[i].allFinite()) ranges.push_back(cloud.points[i].cast<double>().norm());
  }
  if (ranges.empty()) return 0.0;
  const auto nth = ranges.begin() + static_cast<std::ptrdiff_t>(0.99 * (ranges.size() - 1));
  std::nth_element(ranges.begin(), nth, ranges.end());
  return *nth;
}

LocalVoxelMap::LocalVoxelMap(double voxel_size, int max_points_per_voxel)
    : voxel_(voxel_size > 0 ? voxel_size : 1.0),
      inverse_voxel_(1.0 / voxel_),
      max_points_(std::max(1, max_points_per_voxel)) {}

Eigen::Vector3i LocalVoxelMap::Key(const Eigen::Vector3d& p) const {
  return VoxelOf(p, voxel_, inverse_voxel_);
}

std::size_t LocalVoxelMap::size() const {
  std::size_t n = 0;
  for (const auto& cell : cells_) n += cell.size();
  return n;
}

void LocalVoxelMap::Clear() {
  index_.Reset(0);
  occupied_.Clear();
  keys_.clear();
  cells_.clear();
}

void LocalVoxelMap::Insert(const std::vector<ShapedPoint>& points_sensor,
                           const Pose& T_world_sensor, double reach) {
  const Eigen::Matrix3d R = T_world_sensor.linear();
  for (const ShapedPoint& point : points_sensor) {
    const Eigen::Vector3d p = T_world_sensor * point.position;
    const Eigen::Vector3i key = Key(p);
    bool inserted = false;
    const int v = index_.Insert(key, &inserted);
    if (inserted) {
      keys_.push_back(key);
      cells_.emplace_back();
      occupied_.Set(key);
    }
    std::vector<MapPoint>& cell = cells_[static_cast<std::size_t>(v)];
    if (static_cast<int>(cell.size()) >= max_points_) continue;
    cell.push_back({p, R * point.shape * R.transpose()});
  }
  if (!(reach > 0)) return;
  // Voxels out of reach are dropped; the survivors keep their order and are indexed anew.
  const Eigen::Vector3d origin = T_world_sensor.translation();
  const double limit2 = (reach + voxel_) * (reach + voxel_);
  std::size_t kept = 0;
  for (std::size_t v = 0; v < cells_.size(); ++v) {
    if ((cells_[v].front().position - origin).squaredNorm() > limit2) continue;
    if (kept != v) {
      keys_[kept] = keys_[v];
      cells_[kept] = std::move(cells_[v]);
    }
    ++kept;
  }
  if (kept == cells_.size()) return;
  keys_.resize(kept);
  cells_.resize(kept);
  index_.Reset(kept);
  occupied_.Clear();
  for (const Eigen::Vector3i& key : keys_) {
    bool inserted = false;
    index_.Insert(key, &inserted);
    occupied_.Set(key);
  }
}

const LocalVoxelMap::MapPoint* LocalVoxelMap::Nearest(const Eigen::Vector3d& q,
                                                      const Eigen::Matrix3d& shape) const {
  return NearestWithin(q, shape, std::numeric_limits<double>::infinity());
}

const LocalVoxelMap::MapPoint* LocalVoxelMap::NearestWithin(const Eigen::Vector3d& q,
                                                            const Eigen::Matrix3d& shape,
                                                            double max_distance2) const {
  // The query's own voxel first, then its 26 neighbours, each skipped when its box is farther
  // than the best pair so far (exact: only points that cannot win are skipped).
  const Eigen::Vector3i key = Key(q);
  const Eigen::Vector3d offset = q - key.cast<double>() * voxel_;  // in [0, voxel)^3
  // The squared gap from q to the voxel before, at and after its own along each axis.
  double gap2[3][3];
  for (int a = 0; a < 3; ++a) {
    gap2[a][0] = offset[a] * offset[a];
    gap2[a][1] = 0.0;
    gap2[a][2] = (voxel_ - offset[a]) * (voxel_ - offset[a]);
  }
  const MapPoint* best = nullptr;
  double best_d2 = max_distance2;
  auto visit = [&](int dx, int dy, int dz) {
    const double box2 = (gap2[0][dx + 1] + gap2[1][dy + 1]) + gap2[2][dz + 1];
    if (box2 > best_d2) return;
    const Eigen::Vector3i neighbour = key + Eigen::Vector3i(dx, dy, dz);
    if (!occupied_.MaybeSet(neighbour)) return;
    const int v = index_.Find(neighbour);
    if (v < 0) return;
    for (const MapPoint& m : cells_[static_cast<std::size_t>(v)]) {
      const double d2 = (m.position - q).squaredNorm();
      if (!(d2 < best_d2 || (best == nullptr && d2 <= best_d2))) continue;
      // Same kind of structure, oriented alike: ||M_a - M_b||_F = sqrt(2) sin(angle) for two
      // surfaces (about 20 deg at 0.5), at least 1 between a surface and an edge.
      if ((m.shape - shape).squaredNorm() > 0.25) continue;
      best_d2 = d2;
      best = &m;
    }
  };
  visit(0, 0, 0);
  for (int dx = -1; dx <= 1; ++dx) {
    if (gap2[0][dx + 1] > best_d2) continue;  // every voxel of this slab is too far
    for (int dy = -1; dy <= 1; ++dy) {
      if (gap2[0][dx + 1] + gap2[1][dy + 1] > best_d2) continue;
      for (int dz = -1; dz <= 1; ++dz) {
        if (dx != 0 || dy != 0 || dz != 0) visit(dx, dy, dz);
      }
    }
  }
  return best;
}

namespace {

/// Each source point's map point (null: none within reach), from the last search.
using MapPairs = std::vector<const LocalVoxelMap::MapPoint*>;

/// The Gauss-Newton sums of one iteration at T_prev_curr.
struct PairSums {
  Eigen::MatrixXd H;
  Eigen::VectorXd g;
  std::vector<int> support;
  int count = 0;
  double sum_sq = 0.0;
};

/// AccumulatePairs for K directions (Eigen::Dynamic: any number up to six).
template <int K>
PairSums AccumulatePairsOf(const LocalVoxelMap& map, const Pose& T_world_prev,
                           const std::vector<ShapedPoint>& source, const Pose& T,
                           const Eigen::MatrixXd& D, const std::vector<char>& is_translation,
                           MapPairs& pairs, bool search) {
  // At most six directions: fixed-capacity matrices keep the loop free of heap allocations.
  using MatK = Eigen::Matrix<double, K, K, 0, 6, 6>;
  using Mat3K = Eigen::Matrix<double, 3, K, 0, 3, 6>;
  using VecK = Eigen::Matrix<double, K, 1, 0, 6, 1>;
  const int k = static_cast<int>(D.cols());
  MatK H = MatK::Zero(k, k);
  VecK g = VecK::Zero(k);
  PairSums s;
  s.support.assign(k, 0);
  const Eigen::Matrix3d R_wp = T_world_prev.linear();
  const Pose T_world_curr = T_world_prev * T;
  // Residuals beyond a tenth of a voxel weigh less (Huber): the map is thinned to half a voxel,
  // so a correct pair's residual is mostly well inside that.
  const double huber = 0.1 * map.voxel_size();
  const double max_distance2 = map.voxel_size() * map.voxel_size();
  const Mat3K D_t = D.topRows<3>();
  const Mat3K D_r = D.bottomRows<3>();
  Mat3K J(3, k), MJ(3, k);
  const Eigen::Matrix3d R_wc = T_world_curr.linear();
  if (search) pairs.assign(source.size(), nullptr);
  for (std::size_t i = 0; i < source.size(); ++i) {
    const ShapedPoint& point = source[i];
    const Eigen::Vector3d& p = point.position;
    const Eigen::Vector3d q = T_world_curr * p;
    if (search) {
      pairs[i] = map.NearestWithin(q, R_wc * point.shape * R_wc.transpose(), max_distance2);
    }
    const LocalVoxelMap::MapPoint* m = pairs[i];
    if (m == nullptr) continue;
    const Eigen::Vector3d r = q - m->position;
    const Eigen::Matrix3d& M = m->shape;
    // d q / d(dt, dtheta) at the previous frame (geometry.hpp): R_wp [I, -[R p]_x].
    const Eigen::Vector3d rp = T.linear() * p;
    J.noalias() = R_wp * (D_t - Skew(rp) * D_r);
    const Eigen::Vector3d Mr = M * r;
    const double e2 = r.dot(Mr);
    const double e = std::sqrt(e2);
    const double w = e <= huber ? 1.0 : huber / e;
    MJ.noalias() = M * J;
    H.noalias() += w * J.transpose() * MJ;
    g.noalias() += w * J.transpose() * Mr;
    const double lever = std::max(rp.norm(), 1e-9);
    for (int i = 0; i < k; ++i) {
      const double moved = std::sqrt(std::max(0.0, J.col(i).dot(MJ.col(i))));
      if ((is_translation[i] ? moved : moved / lever) > 0.5) ++s.support[i];
    }
    ++s.count;
    s.sum_sq += e2;
  }
  s.H = H;
  s.g = g;
  return s;
}

/// The Gauss-Newton sums of one iteration at T_prev_curr; all six directions (the usual case on
/// the local map) with fixed-size matrices.
PairSums AccumulatePairs(const LocalVoxelMap& map, const Pose& T_world_prev,
                         const std::vector<ShapedPoint>& source, const Pose& T,
                         const Eigen::MatrixXd& D, const std::vector<char>& is_translation,
                         MapPairs& pairs, bool search) {
  if (D.cols() == 6) {
    return AccumulatePairsOf<6>(map, T_world_prev, source, T, D, is_translation, pairs, search);
  }
  return AccumulatePairsOf<Eigen::Dynamic>(map, T_world_prev, source, T, D, is_translation, pairs,
                                           search);
}

/// The farthest a source point within `reach` of the sensor moves between poses a and b of the
/// current frame: at most |t_b - t_a| + angle(R_a^T R_b) reach.
double LargestShift(const Pose& a, const Pose& b, double reach) {
  const Pose d = a.inverse() * b;
  return d.translation().norm() + Eigen::AngleAxisd(d.linear()).angle() * reach;
}

}  // namespace

MapAlignmentResult AlignToLocalMap(const LocalVoxelMap& map, const Pose& T_world_prev,
                                   const std::vector<ShapedPoint>& source, const Pose& T_init,
                                   const Eigen::MatrixXd& D, const Eigen::MatrixXd& prior_covariance,
                                   const LocalMapConfig& config) {
  MapAlignmentResult res;
  res.T_prev_curr = T_init;
  const int k = static_cast<int>(D.cols());
  res.information = Eigen::MatrixXd::Zero(k, k);
  res.covariance = prior_covariance;
  res.support.assign(k, 0);
  if (!internal::DirectionsUsable(D, prior_covariance) || map.empty() || source.empty()) return res;
  const Eigen::MatrixXd h_prior = internal::PriorInformation(prior_covariance);
  std::vector<char> is_translation(k);
  for (int i = 0; i < k; ++i) is_translation[i] = IsTranslation(D.col(i));
  // Floor of the residual sigma: neighbouring pairs are correlated, so the information from
  // their count is optimistic; a tenth of a voxel keeps it in check.
  const double sigma_floor2 = std::pow(0.1 * map.voxel_size(), 2);
  // The pairs are searched again only once the points have moved by more than 3 % of a voxel
  // since the last search: the map is thinned to half a voxel, so a nearest neighbour hardly
  // changes below that, and the later Gauss-Newton steps are far smaller.
  double reach2 = 0.0;
  for (const ShapedPoint& p : source) reach2 = std::max(reach2, p.position.squaredNorm());
  const double reach = std::sqrt(reach2), search_again = 0.03 * map.voxel_size();
  MapPairs pairs;
  Pose T_searched = T_init;
  Eigen::VectorXd y = Eigen::VectorXd::Zero(k);
  for (int it = 0; it < config.max_iterations; ++it) {
    const Pose T = BoxPlus(T_init, D * y);
    const bool search = it == 0 || LargestShift(T_searched, T, reach) > search_again;
    if (search) T_searched = T;
    const PairSums s =
        AccumulatePairs(map, T_world_prev, source, T, D, is_translation, pairs, search);
    res.iterations = it + 1;
    if (s.count < std::max(config.min_support, 6)) return res;  // valid stays false
    res.correspondences = s.count;
    res.support = s.support;
    res.residual_rms = std::sqrt(s.sum_sq / s.count);
    const double sigma2 = std::max(sigma_floor2, s.sum_sq / s.count);
    res.information = s.H / sigma2;
    Eigen::VectorXd step;
    if (!internal::PriorStep(res.information, s.g / sigma2, h_prior, y, &step, &res.covariance)) {
      return res;
    }
    y += step;
    if (step.norm() < 1e-5) {
      res.converged = true;
      break;
    }
  }
  res.T_prev_curr = BoxPlus(T_init, D * y);
  res.valid = res.T_prev_curr.matrix().allFinite() && res.covariance.allFinite();
  return res;
}

MapAlignmentResult AlignScansCoarseToFine(const datasets::OrganizedCloud& prev,
                                          const datasets::OrganizedCloud& curr,
                                          const Pose& T_init, const Matrix6d& prior_covariance,
                                          double voxel, const LocalMapConfig& config) {
  MapAlignmentResult out;
  out.T_prev_curr = T_init;
  Pose T = T_init;
  for (const double scale : {4.0, 2.0, 1.0}) {
    const double v = voxel * scale;
    LocalVoxelMap map(v, config.max_points_per_voxel);
    map.Insert(ScanStructure(prev, nullptr, v), Pose::Identity(), 0.0);
    const MapAlignmentResult a =
        AlignToLocalMap(map, Pose::Identity(), ScanStructure(curr, nullptr, v), T,
                        Matrix6d::Identity(), prior_covariance, config);
    if (!a.valid) return out;  // valid stays false
    T = a.T_prev_curr;
    out = a;
  }
  return out;
}

namespace {

/// Directions (indices into the columns of `dirs`) the pairs alone pin down: enough support and
/// a marginal sigma below the configured limit.
std::vector<int> DeterminedDirections(const MapAlignmentResult& a, const Eigen::MatrixXd& dirs,
                                      const LocalMapConfig& config) {
  std::vector<int> keep;
  const int m = static_cast<int>(dirs.cols());
  const Eigen::MatrixXd cov =
      (a.information + Eigen::MatrixXd::Identity(m, m) * 1e-12).ldlt().solve(
          Eigen::MatrixXd::Identity(m, m));
  for (int i = 0; i < m; ++i) {
    const double max_sigma =
        IsTranslation(dirs.col(i)) ? config.max_translation_sigma : config.max_rotation_sigma;
    if (a.support[i] >= config.min_support && std::isfinite(cov(i, i)) &&
        std::sqrt(std::max(cov(i, i), 0.0)) < max_sigma) {
      keep.push_back(i);
    }
  }
  return keep;
}

Eigen::MatrixXd Columns(const Eigen::MatrixXd& D, const std::vector<int>& keep) {
  Eigen::MatrixXd out(6, keep.size());
  for (std::size_t i = 0; i < keep.size(); ++i) out.col(i) = D.col(keep[i]);
  return out;
}

}  // namespace

bool FillDegenerateFromLocalMap(const LocalVoxelMap& map, const Pose& T_world_prev,
                                const std::vector<ShapedPoint>& source,
                                const LocalMapConfig& config, RegistrationResult* result) {
  const int k = static_cast<int>(result->degenerate_directions.size());
  if (k == 0) return false;
  Eigen::MatrixXd D(6, k);
  for (int i = 0; i < k; ++i) D.col(i) = result->degenerate_directions[i];
  const Pose T_planes = result->T_prev_curr;
  MapAlignmentResult a = AlignToLocalMap(map, T_world_prev, source, T_planes, D,
                                         D.transpose() * result->covariance * D, config);
  if (!a.valid) return false;
  const std::vector<int> keep = DeterminedDirections(a, D, config);
  if (keep.empty()) return false;
  Eigen::MatrixXd Dk = D;
  if (static_cast<int>(keep.size()) < k) {
    // Again along the determined directions only, so the others stay exactly at the prior.
    Dk = Columns(D, keep);
    a = AlignToLocalMap(map, T_world_prev, source, T_planes, Dk,
                        Dk.transpose() * result->covariance * Dk, config);
    if (!a.valid || DeterminedDirections(a, Dk, config).size() != keep.size()) return false;
  }
  // A correction the prior finds implausible is more likely a wrong convergence (a repetitive
  // structure, too few pairs) than the motion.
  const Eigen::VectorXd y = Dk.transpose() * BoxMinus(a.T_prev_curr, T_planes);
  const Eigen::MatrixXd prior_y = Dk.transpose() * result->covariance * Dk;
  if (!(y.dot(prior_y.ldlt().solve(y)) <= Chi2Quantile999(static_cast<double>(y.size())))) {
    return false;
  }
  // Unchanged outside span(Dk) (the directions are orthonormal), the alignment's inside.
  const Matrix6d Q = Matrix6d::Identity() - Dk * Dk.transpose();
  Matrix6d cov = Q * result->covariance * Q + Dk * a.covariance * Dk.transpose();
  cov = 0.5 * (cov + cov.transpose());
  if (!cov.allFinite() || !a.T_prev_curr.matrix().allFinite()) return false;
  result->T_prev_curr = a.T_prev_curr;
  result->covariance = cov;
  result->used_icp = true;
  result->point_directions = static_cast<int>(keep.size());
  result->prior_directions = k - static_cast<int>(keep.size());
  result->prior_translations = internal::PriorTranslationsAfter(
      result->prior_translations, result->prior_directions, D, keep);
  result->used_prior = result->prior_directions > 0;
  return true;
}

bool RefineWithLocalMap(const LocalVoxelMap& map, const Pose& T_world_prev,
                        const std::vector<ShapedPoint>& source, const LocalMapConfig& config,
                        RegistrationResult* result) {
  const Matrix6d prior = result->covariance;
  const MapAlignmentResult a = AlignToLocalMap(map, T_world_prev, source, result->T_prev_curr,
                                               Matrix6d::Identity(), prior, config);
  if (!a.valid) return false;
  const Vector6d y = BoxMinus(a.T_prev_curr, result->T_prev_curr);
  if (!(y.dot(prior.ldlt().solve(y)) <= Chi2Quantile999(6.0))) return false;
  Matrix6d cov = 0.5 * (a.covariance + a.covariance.transpose());
  if (!cov.allFinite() || !a.T_prev_curr.matrix().allFinite()) return false;
  result->T_prev_curr = a.T_prev_curr;
  result->covariance = cov;
  return true;
}

std::string ConstraintSource(const RegistrationResult& result) {
  std::string out;
  auto add = [&](const char* part) { out += (out.empty() ? "" : "+") + std::string(part); };
  if (result.degenerate_directions.size() < 6) add("planes");
  if (result.extent_directions > 0) add("extent");
  if (result.point_directions > 0) add("points");
  if (result.prior_directions > 0 || out.empty()) add("prior");
  return out;
}

}  // namespace planeslam::registration
