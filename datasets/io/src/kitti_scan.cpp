#include "planeslam/datasets/kitti_scan.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>

#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/input_limits.hpp"
#include "planeslam/datasets/trajectory_io.hpp"
#include "reader_util.hpp"

namespace planeslam::datasets {

namespace fs = std::filesystem;

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDegToRad = kPi / 180.0;

int ElevationRow(double elevation, const SensorConfig& config) {
  const double top = config.lidar_elevation_max_deg * kDegToRad;
  const double bottom = config.lidar_elevation_min_deg * kDegToRad;
  const double step = config.lidar_rows > 1 ? (top - bottom) / (config.lidar_rows - 1) : 1.0;
  const double row = std::round((top - elevation) / step);
  if (row < 0 || row >= config.lidar_rows) return -1;
  return static_cast<int>(row);
}

/// The number of points of a scan of `size` bytes; IoError naming `name` when the size is not
/// that of a KITTI scan within the input limits.
std::size_t KittiPointCount(std::size_t size, const std::string& name) {
  if (size == 0) throw IoError(name, "empty scan (0 bytes)");
  if (size % 16 != 0) {
    throw IoError(name, "truncated or not a KITTI scan: size " + std::to_string(size) +
                            " bytes is not a multiple of 16 (float32 x y z reflectance per point)");
  }
  const std::size_t n = size / 16;
  if (static_cast<std::int64_t>(n) > GlobalInputLimits().max_points) {
    throw IoError(name, std::to_string(n) + " points exceed the input limits");
  }
  return n;
}

/// A KITTI scan lists returns only: a NaN or infinite coordinate is a corrupt file, and a scan
/// whose points all sit at the origin holds no return.
void CheckKittiPoints(const std::vector<LidarPoint>& points, const std::string& name) {
  const std::size_t n = points.size();
  bool any_return = false;
  for (std::size_t i = 0; i < n; ++i) {
    const LidarPoint& p = points[i];
    if (!std::isfinite(p.x()) || !std::isfinite(p.y()) || !std::isfinite(p.z())) {
      throw IoError(name, "point " + std::to_string(i) + " of " + std::to_string(n) +
                              " has a NaN or infinite coordinate (corrupt scan)");
    }
    any_return = any_return || p.x() != 0.0f || p.y() != 0.0f || p.z() != 0.0f;
  }
  if (!any_return) {
    throw IoError(name, "empty scan: all " + std::to_string(n) + " points are at the origin");
  }
}

}  // namespace

std::vector<LidarPoint> ParseKittiScan(const std::string& bytes, const std::string& name) {
  std::vector<LidarPoint> points(KittiPointCount(bytes.size(), name));
  // Vector4f is 4 packed floats (16 bytes, no padding).
  std::memcpy(static_cast<void*>(points.data()), bytes.data(), bytes.size());
  CheckKittiPoints(points, name);
  return points;
}

std::vector<LidarPoint> ReadKittiScan(const std::string& path) {
  // Read straight into the points: the file is their memory image.
  std::size_t size = 0;
  std::ifstream in = detail::OpenWholeFile(path, GlobalInputLimits().max_points * 16, &size);
  std::vector<LidarPoint> points(KittiPointCount(size, path));
  in.read(reinterpret_cast<char*>(points.data()), static_cast<std::streamsize>(size));
  if (static_cast<std::uint64_t>(in.gcount()) != size) throw IoError(path, "read failed");
  CheckKittiPoints(points, path);
  return points;
}

namespace {

// Azimuths: glibc's atan2f costs more than the rest of reading a scan, so every point's azimuth
// is first approximated by a branch-free polynomial that the compiler vectorises (Cephes' atanf
// on [0, 1] after folding the octants; within 1e-6 rad of std::atan2, see the tests). The
// approximation only feeds comparisons (octant and ring-wrap tests, column and half-column
// boundaries); where it lies within kAzimuthMargin of a value it is compared with, the point's
// azimuth is computed again with std::atan2, so the decisions are exactly those of std::atan2.
constexpr float kAzimuthMargin = 4e-6f;

// The vector loops below are compiled twice: for the baseline and, on x86-64, for AVX2 (taken
// where the processor has it). The code is the same; only the vector width differs.
std::atomic<bool> avx2_clones{true};  // internal::UseAvx2Clones

#if defined(__x86_64__)
#define PLANESLAM_AVX2_CLONE __attribute__((target("avx2")))
bool HasAvx2() {
  static const bool avx2 = __builtin_cpu_supports("avx2");
  return avx2 && avx2_clones.load(std::memory_order_relaxed);
}
#else
#define PLANESLAM_AVX2_CLONE
bool HasAvx2() { return false; }
#endif

inline void ApproximateAzimuthsBody(const float* xyzw, std::size_t n, float* out) {
  constexpr float kHalfPi = 1.57079632679489662f, kQuarterPi = 0.785398163397448310f;
  constexpr float kPiF = 3.14159265358979324f, kTanEighthPi = 0.414213562373095049f;
  for (std::size_t i = 0; i < n; ++i) {
    const float x = xyzw[4 * i], y = xyzw[4 * i + 1];
    const float ax = std::fabs(x), ay = std::fabs(y);
    const float a = std::min(ax, ay) / std::max(ax, ay);  // in [0, 1]
    const bool upper = a > kTanEighthPi;
    const float folded = (a - 1.0f) / (a + 1.0f);  // computed either way: no branch in the loop
    const float t = upper ? folded : a;
    const float z = t * t;
    const float series = ((8.05374449538e-2f * z - 1.38776856032e-1f) * z + 1.99777106478e-1f) * z -
                         3.33329491539e-1f;
    float r = series * z * t + t;  // atan(t) for |t| <= tan(pi / 8)
    r = upper ? r + kQuarterPi : r;
    r = ay > ax ? kHalfPi - r : r;
    r = x < 0.0f ? kPiF - r : r;
    out[i] = y < 0.0f ? -r : r;
  }
}

PLANESLAM_AVX2_CLONE void ApproximateAzimuthsAvx2(const float* xyzw, std::size_t n, float* out) {
  ApproximateAzimuthsBody(xyzw, n, out);
}

/// Every point's range, summed as Eigen's norm() sums it (x^2 + (y^2 + z^2)), and its column
/// position (pi - azimuth) cols / (2 pi) from the approximate azimuth, in a loop the compiler
/// vectorises. ProjectToRangeImage checks the column against the margin.
inline void RangesAndColumnsBody(const float* xyzw, const float* azimuths, std::size_t n,
                                 double columns_per_radian, double* ranges, double* columns) {
  for (std::size_t i = 0; i < n; ++i) {
    const double x = xyzw[4 * i], y = xyzw[4 * i + 1], z = xyzw[4 * i + 2];
    ranges[i] = std::sqrt(x * x + (y * y + z * z));
    columns[i] = (kPi - static_cast<double>(azimuths[i])) * columns_per_radian;
  }
}

PLANESLAM_AVX2_CLONE void RangesAndColumnsAvx2(const float* xyzw, const float* azimuths,
                                               std::size_t n, double columns_per_radian,
                                               double* ranges, double* columns) {
  RangesAndColumnsBody(xyzw, azimuths, n, columns_per_radian, ranges, columns);
}

/// Every point's slope z / r, r = sqrt(x^2 + y^2); NaN where r is 0 or not finite, or z is not
/// finite. In a loop the compiler vectorises.
inline void SlopesBody(const float* xyzw, std::size_t n, double* slopes) {
  constexpr double kMax = std::numeric_limits<double>::max();
  for (std::size_t i = 0; i < n; ++i) {
    const double x = xyzw[4 * i], y = xyzw[4 * i + 1], z = xyzw[4 * i + 2];
    const double r = std::sqrt(x * x + y * y);
    const bool valid = std::abs(r) <= kMax && std::abs(z) <= kMax && r != 0.0;
    slopes[i] = valid ? z / r : std::numeric_limits<double>::quiet_NaN();
  }
}

PLANESLAM_AVX2_CLONE void SlopesAvx2(const float* xyzw, std::size_t n, double* slopes) {
  SlopesBody(xyzw, n, slopes);
}

/// True when `az` (an approximation) may lie on the other side of 0, +-pi/2 or +-pi than
/// std::atan2's value: the values the ring recovery compares azimuths with.
bool NearQuadrantEdge(float az) {
  constexpr float kHalfPi = 1.57079632679489662f, kPiF = 3.14159265358979324f;
  const float a = std::fabs(az);
  return a < kAzimuthMargin || std::fabs(a - kHalfPi) < kAzimuthMargin || a > kPiF - kAzimuthMargin;
}

}  // namespace

namespace internal {

void UseAvx2Clones(bool use) { avx2_clones.store(use, std::memory_order_relaxed); }

void ApproximateAzimuths(const std::vector<LidarPoint>& scan, std::vector<float>* azimuths) {
  static_assert(sizeof(LidarPoint) == 4 * sizeof(float), "LidarPoint is four packed floats");
  azimuths->resize(scan.size());
  const float* xyzw = scan.empty() ? nullptr : scan.front().data();
  (HasAvx2() ? ApproximateAzimuthsAvx2 : ApproximateAzimuthsBody)(xyzw, scan.size(),
                                                                  azimuths->data());
}

}  // namespace internal

namespace {

/// RecoverRings, also keeping each point's azimuth for the projection: approximate, or std::atan2's
/// near 0, +-pi/2 and +-pi; NaN for a non-finite point or one on the z axis.
int RecoverRingsAndAzimuths(const std::vector<LidarPoint>& scan, std::vector<int>* rings,
                            std::vector<float>* azimuths) {
  rings->assign(scan.size(), 0);
  // Approximated in place, then made exact where a comparison needs it and NaN where undefined.
  std::vector<float> own;
  std::vector<float>& az_of = azimuths ? *azimuths : own;
  internal::ApproximateAzimuths(scan, &az_of);
  // KITTI stores each laser as one counter-clockwise sweep that starts just left of straight
  // ahead (azimuth 0+), wraps from +pi to -pi behind the car and ends just right of ahead (0-).
  // A new laser starts where the azimuth crosses from slightly negative to slightly positive
  // after the sweep has wrapped; requiring the wrap ignores jitter around 0 at a sweep's start.
  int ring = 0;
  bool wrapped = false;
  double prev = std::numeric_limits<double>::quiet_NaN();
  for (std::size_t i = 0; i < scan.size(); ++i) {
    const LidarPoint& p = scan[i];
    if (!std::isfinite(p.x()) || !std::isfinite(p.y()) || (p.x() == 0 && p.y() == 0)) {
      (*rings)[i] = ring;
      az_of[i] = std::numeric_limits<float>::quiet_NaN();
      continue;
    }
    if (NearQuadrantEdge(az_of[i])) az_of[i] = std::atan2(p.y(), p.x());
    const double az = az_of[i];
    if (std::isfinite(prev)) {
      if (prev > kPi / 2 && az < -kPi / 2) {
        wrapped = true;
      } else if (wrapped && prev < 0 && prev > -kPi / 2 && az >= 0 && az < kPi / 2) {
        ++ring;
        wrapped = false;
      }
    }
    prev = az;
    (*rings)[i] = ring;
  }
  const int count = scan.empty() ? 0 : ring + 1;
  // Renumber by mean slope z / r (elevation's tangent), highest first, so rows go top to bottom.
  // A laser's points share one elevation up to noise, so this is the order of the elevations.
  // The slopes are computed in vector code; each ring's sum runs in a register, in scan order.
  std::vector<double> slopes(scan.size());
  if (!scan.empty()) {
    (HasAvx2() ? SlopesAvx2 : SlopesBody)(scan.front().data(), scan.size(), slopes.data());
  }
  std::vector<double> sum(count, 0.0);
  std::vector<std::size_t> num(count, 0);
  int current = 0;
  double running = 0.0;
  for (std::size_t i = 0; i < scan.size(); ++i) {
    if (std::isnan(slopes[i])) continue;
    if ((*rings)[i] != current) {
      sum[current] = running;
      current = (*rings)[i];
      running = sum[current];
    }
    running += slopes[i];
    ++num[current];
  }
  if (count > 0) sum[current] = running;
  std::vector<int> order(count);
  for (int k = 0; k < count; ++k) order[k] = k;
  auto mean = [&](int k) { return num[k] ? sum[k] / num[k] : -1e9; };
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return mean(a) > mean(b); });
  std::vector<int> rank(count);
  for (int k = 0; k < count; ++k) rank[order[k]] = k;
  for (int& r : *rings) r = rank[r];
  return count;
}

}  // namespace

int RecoverRings(const std::vector<LidarPoint>& scan, std::vector<int>* rings) {
  return RecoverRingsAndAzimuths(scan, rings, nullptr);
}

OrganizedCloud ProjectToRangeImage(const std::vector<LidarPoint>& scan, const SensorConfig& config,
                                   RangeProjectionStats* stats) {
  config.ValidateOrThrow();
  RangeProjectionStats s;
  s.points = scan.size();
  const int rows = config.lidar_rows, cols = config.lidar_cols;
  OrganizedCloud cloud(cols, rows, SensorModel::kSpherical);
  std::vector<float> best(static_cast<std::size_t>(rows) * cols,
                          std::numeric_limits<float>::infinity());
  std::vector<int> rings;
  std::vector<float> azimuths;  // approximate or exact (see kAzimuthMargin); NaN: not computed
  if (config.lidar_row_mode == "scan_order") {
    s.used_scan_order = RecoverRingsAndAzimuths(scan, &rings, &azimuths) == rows;
  } else {
    internal::ApproximateAzimuths(scan, &azimuths);
  }
  // Columns and the half-column leans change at multiples of half a column: an azimuth within
  // the margin of one is computed exactly.
  const double margin = 2.0 * kAzimuthMargin / (2.0 * kPi) * cols;  // in half columns
  std::vector<double> ranges(scan.size()), columns(scan.size());
  if (!scan.empty()) {
    (HasAvx2() ? RangesAndColumnsAvx2 : RangesAndColumnsBody)(scan.front().data(), azimuths.data(),
                                                              scan.size(), cols / (2.0 * kPi),
                                                              ranges.data(), columns.data());
  }
  for (std::size_t i = 0; i < scan.size(); ++i) {
    const LidarPoint& p = scan[i];
    const double range = ranges[i];
    if (!std::isfinite(range) || range == 0.0) {
      ++s.invalid;
      continue;
    }
    if (range < config.min_depth || (config.max_depth > 0.0 && range > config.max_depth)) {
      ++s.outside_range;
      continue;
    }
    int row;
    if (s.used_scan_order) {
      row = rings[i];
    } else {
      row = ElevationRow(std::atan2(p.z(), std::hypot(p.x(), p.y())), config);
      if (row < 0) {
        ++s.outside_elevation;
        continue;
      }
    }
    double u = columns[i];
    if (!(std::abs(2.0 * u - std::round(2.0 * u)) >= margin)) {  // also where NaN
      const double az = std::atan2(p.y(), p.x());                // (-pi, pi]
      u = (kPi - az) / (2.0 * kPi) * cols;
    }
    const int col = std::clamp(static_cast<int>(std::floor(u)), 0, cols - 1);
    const std::size_t row_start = static_cast<std::size_t>(row) * cols;
    std::size_t cell = row_start + col;
    if (std::isfinite(best[cell]) && config.lidar_column_shift > 0) {
      // Try free columns nearest first, on the side the point leans to first; azimuth wraps.
      const int lean = (u - std::floor(u)) < 0.5 ? -1 : 1;
      for (int d = 1; d <= config.lidar_column_shift; ++d) {
        bool found = false;
        for (int side : {lean, -lean}) {
          const int c = ((col + side * d) % cols + cols) % cols;
          if (!std::isfinite(best[row_start + c])) {
            cell = row_start + c;
            found = true;
            ++s.shifted;
            break;
          }
        }
        if (found) break;
      }
    }
    if (std::isfinite(best[cell])) ++s.collisions;  // one of the two is lost
    if (range < best[cell]) {
      best[cell] = static_cast<float>(range);
      cloud.points[cell] = p.head<3>();
    }
  }
  s.placed = s.points - s.invalid - s.outside_elevation - s.outside_range - s.collisions;
  if (stats) *stats = s;
  return cloud;
}

OrganizedCloud ReadKittiRangeImage(const std::string& path, const SensorConfig& config,
                                   RangeProjectionStats* stats) {
  return ProjectToRangeImage(ReadKittiScan(path), config, stats);
}

namespace {

// Frame number in a KITTI scan name ("000123.bin" -> 123); -1 when the stem is not all digits.
long FrameNumber(const std::string& path) {
  const std::string stem = fs::path(path).stem().string();
  std::int64_t n = 0;
  if (stem.empty() || stem.size() > 12 || !detail::ParseInt64(stem, &n)) return -1;
  return static_cast<long>(n);
}

// The `Tr:` line of a KITTI calib.txt (velodyne -> camera 0), if any.
std::optional<Pose> ReadVeloToCam(const fs::path& calib) {
  std::error_code ec;
  if (!fs::exists(calib, ec)) return std::nullopt;
  const std::string text = detail::ReadWholeFile(calib.string(), 1 << 20);
  detail::LineReader reader(text, calib.string());
  std::string_view line;
  while (reader.Next(&line)) {
    const auto tok = detail::SplitWhitespace(line);
    if (tok.empty() || (tok[0] != "Tr:" && tok[0] != "Tr_velo_cam:")) continue;
    if (tok.size() != 13)
      throw IoError(calib.string(), reader.line_number(), "Tr needs 12 numbers");
    Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
    for (int k = 0; k < 12; ++k) {
      if (!detail::ParseDouble(tok[k + 1], &m(k / 4, k % 4))) {
        throw IoError(calib.string(), reader.line_number(),
                      "expected a number, got '" + std::string(tok[k + 1]) + "'");
      }
    }
    Pose T;
    T.matrix() = m;
    return T;
  }
  return std::nullopt;
}

}  // namespace

std::unique_ptr<FileSequence> OpenKittiFolder(const std::string& folder,
                                              const SensorConfig& config) {
  config.ValidateOrThrow();
  std::error_code ec;
  fs::path dir = fs::path(folder).lexically_normal();
  if (dir.filename().empty()) dir = dir.parent_path();
  // The scans: the folder's velodyne/ (a KITTI sequence folder) or the folder itself; the
  // sequence's files (times.txt, poses.txt, calib.txt) sit beside velodyne/.
  fs::path scans = dir;
  if (fs::is_directory(dir / "velodyne", ec)) {
    scans = dir / "velodyne";
  } else if (dir.filename() == "velodyne" && dir.has_parent_path()) {
    dir = dir.parent_path();
  }
  auto files = ListFrameFiles(scans.string(), ".bin");
  if (files.empty()) throw IoError(scans.string(), "no .bin files in folder");

  std::vector<std::optional<Pose>> gt;
  std::string poses_path = config.lidar_poses_file;
  if (poses_path.empty() && fs::exists(dir / "poses.txt", ec))
    poses_path = (dir / "poses.txt").string();
  // KITTI's own tree: dataset/sequences/NN/ with the ground truth in dataset/poses/NN.txt.
  const fs::path kitti_poses =
      dir.parent_path().parent_path() / "poses" / (dir.filename().string() + ".txt");
  if (poses_path.empty() && dir.parent_path().filename() == "sequences" &&
      fs::is_regular_file(kitti_poses, ec))
    poses_path = kitti_poses.string();
  if (!poses_path.empty()) {
    const Trajectory poses = ReadKittiTrajectory(poses_path);
    const auto velo_to_cam = ReadVeloToCam(dir / "calib.txt");
    gt.resize(files.size());
    for (std::size_t i = 0; i < files.size(); ++i) {
      const long n = FrameNumber(files[i]);
      if (n < 0) {
        throw IoError(files[i], "cannot match the scan to a pose: its name is not a frame number");
      }
      if (static_cast<std::size_t>(n) >= poses.size()) {
        throw IoError(poses_path, "has " + std::to_string(poses.size()) + " poses, scan " +
                                      fs::path(files[i]).filename().string() + " needs pose " +
                                      std::to_string(n));
      }
      Pose T = poses.poses[n];
      if (velo_to_cam) T = velo_to_cam->inverse() * T * *velo_to_cam;
      gt[i] = T;
    }
  }

  std::vector<double> stamps;
  if (fs::exists(dir / "times.txt", ec)) {
    const std::string path = (dir / "times.txt").string();
    const std::string text = detail::ReadWholeFile(path, detail::MaxInputFileBytes());
    std::vector<double> times;
    detail::LineReader reader(text, path);
    std::string_view line;
    while (reader.Next(&line)) {
      line = detail::Trim(line);
      if (line.empty()) continue;
      double t = 0;
      if (!detail::ParseDouble(line, &t)) {
        throw IoError(path, reader.line_number(), "expected a time in seconds");
      }
      times.push_back(t);
    }
    for (const auto& f : files) {
      const long n = FrameNumber(f);
      if (n < 0 || static_cast<std::size_t>(n) >= times.size()) {
        throw IoError(path, "has " + std::to_string(times.size()) + " times, scan " +
                                fs::path(f).filename().string() + " has none");
      }
      if (!stamps.empty() && !(times[n] > stamps.back())) {
        throw IoError(path, "time of scan " + fs::path(f).filename().string() +
                                " is not after the previous scan's");
      }
      stamps.push_back(times[n]);
    }
  }
  return std::make_unique<FileSequence>(
      dir.filename().string(), std::move(files),
      [config](const std::string& path) { return ReadKittiRangeImage(path, config); },
      std::move(gt), std::move(stamps));
}

}  // namespace planeslam::datasets
