#include "planeslam/datasets/trajectory_io.hpp"

#include <Eigen/SVD>
#include <charconv>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <system_error>

#include "planeslam/datasets/atomic_file.hpp"
#include "planeslam/datasets/errors.hpp"

namespace planeslam::datasets {
namespace {

/// One non-empty, non-comment line with its 1-based number.
struct DataLine {
  long number;
  std::string text;
};

std::vector<DataLine> ReadDataLines(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw IoError(path, "cannot open file");
  std::vector<DataLine> lines;
  std::string line;
  long number = 0;
  while (std::getline(in, line)) {
    ++number;
    if (!line.empty() && line.back() == '\r') line.pop_back();  // files written on Windows
    const std::size_t first = line.find_first_not_of(" \t");
    if (first == std::string::npos || line[first] == '#') continue;
    lines.push_back({number, line});
  }
  if (in.bad()) throw IoError(path, "read error");
  return lines;
}

std::vector<std::string> SplitWhitespace(const std::string& text) {
  std::vector<std::string> tokens;
  std::istringstream is(text);
  std::string token;
  while (is >> token) tokens.push_back(token);
  return tokens;
}

std::vector<std::string> SplitCommas(const std::string& text) {
  std::vector<std::string> tokens;
  std::size_t start = 0;
  while (true) {
    const std::size_t comma = text.find(',', start);
    std::string token =
        text.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
    const std::size_t a = token.find_first_not_of(" \t");
    const std::size_t b = token.find_last_not_of(" \t");
    tokens.push_back(a == std::string::npos ? std::string() : token.substr(a, b - a + 1));
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  return tokens;
}

/// Parses a whole token as a finite double; the error names the column (1-based).
double ParseNumber(const std::string& path, long line, const std::string& token, int column) {
  const char* begin = token.c_str();
  char* end = nullptr;
  errno = 0;
  const double value = std::strtod(begin, &end);
  if (token.empty() || end != begin + token.size()) {
    throw IoError(path, line,
                  "column " + std::to_string(column) + ": '" + token + "' is not a number");
  }
  if (!std::isfinite(value)) {
    throw IoError(path, line,
                  "column " + std::to_string(column) + ": '" + token + "' is not finite");
  }
  return value;
}

std::string ColumnCountMessage(std::size_t got, const std::string& expected) {
  return "expected " + expected + ", got " + std::to_string(got) + " columns";
}

/// Stamps must increase strictly: association and RPE pairing assume it (evo's check() says the
/// same; the TUM tools silently keep the last of duplicate stamps). Returns false when the line
/// must be skipped (a duplicate kept as the first); a duplicate kept as the last replaces the
/// previous pose, which the caller does when this returns true and the stamp equals the last.
bool CheckStampOrder(const std::string& path, long line, const Trajectory& trajectory, double stamp,
                     const TrajectoryReadOptions& options, std::vector<long>* duplicate_lines) {
  if (trajectory.empty()) return true;
  const double previous = trajectory.stamps.back();
  if (stamp == previous) {
    if (options.duplicates == TrajectoryReadOptions::Duplicates::kError) {
      throw IoError(path, line,
                    "duplicate timestamp " + FormatRoundTrip(stamp) + " (stamps must be unique)" +
                        options.duplicate_hint);
    }
    duplicate_lines->push_back(line);
    return options.duplicates == TrajectoryReadOptions::Duplicates::kKeepLast;
  }
  if (stamp < previous) {
    throw IoError(path, line,
                  "timestamp " + FormatRoundTrip(stamp) + " is before the previous one (" +
                      FormatRoundTrip(previous) + "): stamps must be sorted");
  }
  return true;
}

/// Appends a pose, replacing the last one when it has the same stamp (duplicate kept as last).
void AddOrReplace(Trajectory& trajectory, double stamp, const Pose& pose) {
  if (!trajectory.empty() && trajectory.stamps.back() == stamp) {
    trajectory.poses.back() = pose;
    return;
  }
  trajectory.Add(stamp, pose);
}

void AddDuplicateWarning(const std::string& path, const std::vector<long>& lines,
                         const TrajectoryReadOptions& options, TrajectoryReadReport* report) {
  if (lines.empty() || report == nullptr) return;
  std::ostringstream os;
  os << path << ": " << lines.size() << " duplicate timestamp(s) (line";
  for (std::size_t i = 0; i < lines.size() && i < 5; ++i) os << (i ? ", " : " ") << lines[i];
  if (lines.size() > 5) os << ", ...";
  os << "): kept the "
     << (options.duplicates == TrajectoryReadOptions::Duplicates::kKeepLast ? "last" : "first")
     << " pose of each";
  report->warnings.push_back(os.str());
}

Eigen::Quaterniond CheckedQuaternion(const std::string& path, long line, double qw, double qx,
                                     double qy, double qz, const TrajectoryReadOptions& options,
                                     std::size_t* warned) {
  Eigen::Quaterniond q(qw, qx, qy, qz);
  const double deviation = std::abs(q.norm() - 1.0);
  if (!(deviation <= options.max_tolerance)) {
    std::ostringstream os;
    os << "quaternion norm " << q.norm() << " is not 1 (tolerance " << options.max_tolerance << ")";
    throw IoError(path, line, os.str());
  }
  if (deviation > options.silent_tolerance) ++*warned;
  q.normalize();
  return q;
}

void AddNormalisationWarning(const std::string& path, std::size_t warned, const char* what,
                             const TrajectoryReadOptions& options, TrajectoryReadReport* report) {
  if (warned == 0 || report == nullptr) return;
  std::ostringstream os;
  os << path << ": " << warned << " " << what << " off by more than " << options.silent_tolerance
     << " normalised";
  report->warnings.push_back(os.str());
}

void CheckNotEmpty(const std::string& path, const Trajectory& trajectory) {
  if (trajectory.empty()) throw IoError(path, "no poses in file");
}

}  // namespace

std::string ToString(TrajectoryFormat format) {
  switch (format) {
    case TrajectoryFormat::kTum:
      return "tum";
    case TrajectoryFormat::kKitti:
      return "kitti";
    case TrajectoryFormat::kEuroc:
      return "euroc";
  }
  return "?";
}

TrajectoryFormat ParseTrajectoryFormat(const std::string& name) {
  if (name == "tum") return TrajectoryFormat::kTum;
  if (name == "kitti") return TrajectoryFormat::kKitti;
  if (name == "euroc") return TrajectoryFormat::kEuroc;
  throw ConfigError("unknown trajectory format '" + name + "' (expected tum, kitti or euroc)");
}

TrajectoryFormat DetectTrajectoryFormat(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw IoError(path, "cannot open file");
  std::string line;
  long number = 0;
  while (std::getline(in, line)) {
    ++number;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    const std::size_t first = line.find_first_not_of(" \t");
    if (first == std::string::npos || line[first] == '#') continue;
    if (line.find(',') != std::string::npos) return TrajectoryFormat::kEuroc;
    const std::size_t columns = SplitWhitespace(line).size();
    if (columns == 8) return TrajectoryFormat::kTum;
    if (columns == 12) return TrajectoryFormat::kKitti;
    throw IoError(path, number,
                  "cannot detect the format: " + std::to_string(columns) +
                      " columns (TUM has 8, KITTI 12, EuRoC is comma-separated); use --format");
  }
  throw IoError(path, "no poses in file");
}

Trajectory ReadTumTrajectory(const std::string& path, TrajectoryReadReport* report,
                             const TrajectoryReadOptions& options) {
  Trajectory trajectory;
  std::size_t warned = 0;
  std::vector<long> duplicates;
  for (const DataLine& line : ReadDataLines(path)) {
    const std::vector<std::string> tokens = SplitWhitespace(line.text);
    if (tokens.size() != 8) {
      throw IoError(path, line.number,
                    ColumnCountMessage(tokens.size(), "8 columns 't tx ty tz qx qy qz qw' (TUM)"));
    }
    double v[8];
    for (int i = 0; i < 8; ++i) v[i] = ParseNumber(path, line.number, tokens[i], i + 1);
    const Eigen::Quaterniond q =
        CheckedQuaternion(path, line.number, v[7], v[4], v[5], v[6], options, &warned);
    if (!CheckStampOrder(path, line.number, trajectory, v[0], options, &duplicates)) continue;
    Pose pose = Pose::Identity();
    pose.linear() = q.toRotationMatrix();
    pose.translation() = Eigen::Vector3d(v[1], v[2], v[3]);
    AddOrReplace(trajectory, v[0], pose);
  }
  CheckNotEmpty(path, trajectory);
  AddNormalisationWarning(path, warned, "quaternion(s) with a norm", options, report);
  AddDuplicateWarning(path, duplicates, options, report);
  return trajectory;
}

Trajectory ReadKittiTrajectory(const std::string& path, const std::string& times_path,
                               TrajectoryReadReport* report, const TrajectoryReadOptions& options) {
  std::vector<double> times;
  std::vector<long> time_lines;
  if (!times_path.empty()) {
    for (const DataLine& line : ReadDataLines(times_path)) {
      const std::vector<std::string> tokens = SplitWhitespace(line.text);
      if (tokens.size() != 1) {
        throw IoError(times_path, line.number, ColumnCountMessage(tokens.size(), "1 column"));
      }
      const double t = ParseNumber(times_path, line.number, tokens[0], 1);
      if (!times.empty() && !(t > times.back())) {
        throw IoError(times_path, line.number,
                      t == times.back() ? "duplicate timestamp " + FormatRoundTrip(t)
                                        : "timestamp " + FormatRoundTrip(t) +
                                              " is before the previous one: stamps must be "
                                              "sorted");
      }
      times.push_back(t);
      time_lines.push_back(line.number);
    }
  }
  Trajectory trajectory;
  std::size_t warned = 0;
  for (const DataLine& line : ReadDataLines(path)) {
    const std::vector<std::string> tokens = SplitWhitespace(line.text);
    if (tokens.size() != 12) {
      throw IoError(path, line.number,
                    ColumnCountMessage(tokens.size(), "12 columns (KITTI 3x4 [R|t] row-major)"));
    }
    Eigen::Matrix<double, 3, 4> m;
    for (int i = 0; i < 12; ++i) m(i / 4, i % 4) = ParseNumber(path, line.number, tokens[i], i + 1);
    Pose pose = Pose::Identity();
    pose.linear() = m.leftCols<3>();
    pose.translation() = m.col(3);
    // KITTI prints about 7 significant digits, so RᵀR = I only to ~1e-6. Such matrices are kept
    // as written (evo does the same); clearly non-orthonormal ones are projected onto SO(3) with a
    // warning, and garbage is refused.
    const Eigen::Matrix3d r = pose.linear();
    const double deviation = (r.transpose() * r - Eigen::Matrix3d::Identity()).norm();
    if (!(deviation <= options.max_tolerance) || r.determinant() < 0.0) {
      std::ostringstream os;
      os << "rotation is not orthonormal (|RtR - I| = " << deviation << ", det " << r.determinant()
         << ")";
      throw IoError(path, line.number, os.str());
    }
    if (deviation > options.silent_tolerance) {
      ++warned;
      Eigen::JacobiSVD<Eigen::Matrix3d> svd(r, Eigen::ComputeFullU | Eigen::ComputeFullV);
      pose.linear() = svd.matrixU() * svd.matrixV().transpose();
    }
    const std::size_t index = trajectory.size();
    double stamp = static_cast<double>(index);
    if (!times_path.empty()) {
      if (index >= times.size()) {
        throw IoError(times_path, "has " + std::to_string(times.size()) + " stamps but " + path +
                                      " has more poses");
      }
      stamp = times[index];
    }
    trajectory.Add(stamp, pose);
  }
  CheckNotEmpty(path, trajectory);
  if (!times_path.empty() && times.size() != trajectory.size()) {
    throw IoError(times_path, time_lines[trajectory.size()],
                  "has " + std::to_string(times.size()) + " stamps but " + path + " has " +
                      std::to_string(trajectory.size()) + " poses");
  }
  AddNormalisationWarning(path, warned, "rotation matrices with |RtR - I|", options, report);
  return trajectory;
}

Trajectory ReadEurocTrajectory(const std::string& path, TrajectoryReadReport* report,
                               const TrajectoryReadOptions& options) {
  Trajectory trajectory;
  std::size_t warned = 0;
  std::vector<long> duplicates;
  for (const DataLine& line : ReadDataLines(path)) {
    const std::vector<std::string> tokens = SplitCommas(line.text);
    if (tokens.size() < 8) {
      throw IoError(path, line.number,
                    ColumnCountMessage(tokens.size(),
                                       "at least 8 comma-separated columns 't[ns], px, py, pz, "
                                       "qw, qx, qy, qz' (EuRoC)"));
    }
    double v[8];
    for (int i = 0; i < 8; ++i) v[i] = ParseNumber(path, line.number, tokens[i], i + 1);
    const double stamp = v[0] / 1e9;  // nanoseconds, as evo: float(ns) / 1e9
    const Eigen::Quaterniond q =
        CheckedQuaternion(path, line.number, v[4], v[5], v[6], v[7], options, &warned);
    if (!CheckStampOrder(path, line.number, trajectory, stamp, options, &duplicates)) continue;
    Pose pose = Pose::Identity();
    pose.linear() = q.toRotationMatrix();
    pose.translation() = Eigen::Vector3d(v[1], v[2], v[3]);
    AddOrReplace(trajectory, stamp, pose);
  }
  CheckNotEmpty(path, trajectory);
  AddNormalisationWarning(path, warned, "quaternion(s) with a norm", options, report);
  AddDuplicateWarning(path, duplicates, options, report);
  return trajectory;
}

Trajectory ReadTrajectory(const std::string& path, TrajectoryFormat format,
                          TrajectoryReadReport* report, const std::string& kitti_times_path,
                          const TrajectoryReadOptions& options) {
  switch (format) {
    case TrajectoryFormat::kTum:
      return ReadTumTrajectory(path, report, options);
    case TrajectoryFormat::kKitti:
      return ReadKittiTrajectory(path, kitti_times_path, report, options);
    case TrajectoryFormat::kEuroc:
      return ReadEurocTrajectory(path, report, options);
  }
  throw IoError(path, "unknown format");
}

std::string FormatRoundTrip(double value) {
  char buffer[64];
  const std::to_chars_result r = std::to_chars(buffer, buffer + sizeof(buffer), value);
  return std::string(buffer, r.ptr);
}

void WriteTumTrajectory(const std::string& path, const Trajectory& trajectory) {
  PLANESLAM_CHECK(trajectory.stamps.size() == trajectory.poses.size(), "stamps and poses differ");
  AtomicOutputFile out(path);
  std::ostream& os = out.stream();
  os << "# timestamp tx ty tz qx qy qz qw\n";
  for (std::size_t i = 0; i < trajectory.size(); ++i) {
    const Pose& pose = trajectory.poses[i];
    Eigen::Quaterniond q(pose.linear());
    q.normalize();
    if (q.w() < 0.0) q.coeffs() = -q.coeffs();  // one of the two equal quaternions, qw >= 0
    const Eigen::Vector3d t = pose.translation();
    os << FormatRoundTrip(trajectory.stamps[i]) << ' ' << FormatRoundTrip(t.x()) << ' '
       << FormatRoundTrip(t.y()) << ' ' << FormatRoundTrip(t.z()) << ' ' << FormatRoundTrip(q.x())
       << ' ' << FormatRoundTrip(q.y()) << ' ' << FormatRoundTrip(q.z()) << ' '
       << FormatRoundTrip(q.w()) << '\n';
  }
  out.Commit();
}

void WriteKittiTrajectory(const std::string& path, const Trajectory& trajectory,
                          const std::string& times_path) {
  PLANESLAM_CHECK(trajectory.stamps.size() == trajectory.poses.size(), "stamps and poses differ");
  AtomicOutputFile out(path);
  std::ostream& os = out.stream();
  for (const Pose& pose : trajectory.poses) {
    const Eigen::Matrix<double, 3, 4> m = pose.matrix().topRows<3>();
    for (int i = 0; i < 12; ++i) {
      if (i > 0) os << ' ';
      os << FormatRoundTrip(m(i / 4, i % 4));
    }
    os << '\n';
  }
  if (!times_path.empty()) {
    AtomicOutputFile times(times_path);
    for (double t : trajectory.stamps) times.stream() << FormatRoundTrip(t) << '\n';
    times.Commit();
  }
  out.Commit();
}

}  // namespace planeslam::datasets
