#include "planeslam/datasets/file_sequence.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <regex>

#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/pcd_io.hpp"
#include "planeslam/datasets/trajectory_io.hpp"
#include "planeslam/datasets/tum_sequence.hpp"

namespace planeslam::datasets {

namespace fs = std::filesystem;

namespace {

std::string Lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return s;
}

// Natural order: runs of digits compare by numeric value (leading zeros ignored), the rest by
// character; ties fall back to plain comparison so the order is total.
bool NaturalLess(const std::string& a, const std::string& b) {
  std::size_t i = 0, j = 0;
  while (i < a.size() && j < b.size()) {
    const bool da = std::isdigit(static_cast<unsigned char>(a[i]));
    const bool db = std::isdigit(static_cast<unsigned char>(b[j]));
    if (da && db) {
      std::size_t ie = i, je = j;
      while (ie < a.size() && std::isdigit(static_cast<unsigned char>(a[ie]))) ++ie;
      while (je < b.size() && std::isdigit(static_cast<unsigned char>(b[je]))) ++je;
      std::size_t is = i, js = j;
      while (is + 1 < ie && a[is] == '0') ++is;
      while (js + 1 < je && b[js] == '0') ++js;
      if (ie - is != je - js) return ie - is < je - js;
      const int c = a.compare(is, ie - is, b, js, je - js);
      if (c != 0) return c < 0;
      i = ie;
      j = je;
    } else {
      if (a[i] != b[j]) return a[i] < b[j];
      ++i;
      ++j;
    }
  }
  if (a.size() - i != b.size() - j) return a.size() - i < b.size() - j;
  return a < b;
}

// Days since 1970-01-01 of a proleptic Gregorian date (the civil-from-days inverse, era based).
long DaysFromCivil(long y, long m, long d) {
  y -= m <= 2 ? 1 : 0;
  const long era = (y >= 0 ? y : y - 399) / 400;
  const long yoe = y - era * 400;
  const long doy = (153 * (m + (m > 2 ? -3 : 9)) + 2) / 5 + d - 1;
  const long doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
  return era * 146097 + doe - 719468;
}

}  // namespace

std::vector<std::string> ListFrameFiles(const std::string& folder, const std::string& extension) {
  std::error_code ec;
  if (!fs::exists(folder, ec)) throw IoError(folder, "no such folder");
  if (!fs::is_directory(folder, ec)) throw IoError(folder, "not a folder");
  const std::string want = Lower(extension);
  std::vector<std::string> names;
  for (const auto& entry : fs::directory_iterator(folder, ec)) {
    std::error_code e2;
    if (!entry.is_regular_file(e2)) continue;
    if (Lower(entry.path().extension().string()) == want) {
      names.push_back(entry.path().filename().string());
    }
  }
  if (ec) throw IoError(folder, "cannot list folder (" + ec.message() + ")");
  std::sort(names.begin(), names.end(), NaturalLess);
  std::vector<std::string> files;
  files.reserve(names.size());
  for (const auto& n : names) files.push_back((fs::path(folder) / n).string());
  return files;
}

std::optional<double> TimestampFromFileName(const std::string& path) {
  const std::string stem = fs::path(path).stem().string();
  static const std::regex iso(R"((\d{4})(\d{2})(\d{2})T(\d{2})(\d{2})(\d{2})(\.\d+)?)");
  std::smatch m;
  if (std::regex_search(stem, m, iso)) {
    const long days = DaysFromCivil(std::stol(m[1]), std::stol(m[2]), std::stol(m[3]));
    double t = days * 86400.0 + std::stol(m[4]) * 3600.0 + std::stol(m[5]) * 60.0 + std::stol(m[6]);
    if (m[7].matched) t += std::stod("0" + m[7].str());
    return t;
  }
  static const std::regex number(R"(\d+(\.\d+)?)");
  std::optional<double> last;
  for (auto it = std::sregex_iterator(stem.begin(), stem.end(), number);
       it != std::sregex_iterator(); ++it) {
    const std::string s = it->str();
    if (s.size() > 30) continue;
    last = std::stod(s);
  }
  return last;
}

void ApplyRangeLimits(OrganizedCloud* cloud, double min_range, double max_range) {
  if (min_range <= 0.0 && max_range <= 0.0) return;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const bool spherical = cloud->model == SensorModel::kSpherical;
  for (auto& p : cloud->points) {
    if (!OrganizedCloud::IsValid(p)) continue;
    const double r = spherical ? p.norm() : p.z();
    if (r < min_range || (max_range > 0.0 && r > max_range)) p.setConstant(nan);
  }
}

namespace {

/// Stamps from the file names when every name has a number and they increase strictly, else the
/// indices.
std::vector<double> StampsFromFileNames(const std::vector<std::string>& files) {
  std::vector<double> stamps(files.size());
  bool usable = true;
  for (std::size_t i = 0; i < files.size() && usable; ++i) {
    const auto t = TimestampFromFileName(files[i]);
    usable = t.has_value() && (i == 0 || *t > stamps[i - 1]);
    if (usable) stamps[i] = *t;
  }
  if (!usable) {
    for (std::size_t i = 0; i < files.size(); ++i) stamps[i] = static_cast<double>(i);
  }
  return stamps;
}

}  // namespace

FileSequence::FileSequence(std::string name, std::vector<std::string> files, Loader loader,
                           std::vector<std::optional<Pose>> gt, std::vector<double> stamps)
    : name_(std::move(name)),
      files_(std::move(files)),
      stamps_(std::move(stamps)),
      loader_(std::move(loader)),
      gt_(std::move(gt)) {
  PLANESLAM_CHECK(gt_.empty() || gt_.size() == files_.size(), "one pose per file");
  PLANESLAM_CHECK(stamps_.empty() || stamps_.size() == files_.size(), "one stamp per file");
  if (stamps_.empty()) stamps_ = StampsFromFileNames(files_);
}

Frame FileSequence::Load(std::size_t index) const {
  PLANESLAM_CHECK(index < files_.size(), "frame " << index << " of " << files_.size());
  Frame frame;
  frame.index = index;
  frame.timestamp = stamps_[index];
  frame.source = files_[index];
  frame.cloud = loader_(files_[index]);
  if (!gt_.empty()) frame.T_world_sensor_gt = gt_[index];
  return frame;
}

double FileSequence::Timestamp(std::size_t index) const {
  PLANESLAM_CHECK(index < files_.size(), "frame " << index << " of " << files_.size());
  return stamps_[index];
}

std::optional<Pose> FileSequence::GroundTruth(std::size_t index) const {
  PLANESLAM_CHECK(index < files_.size(), "frame " << index << " of " << files_.size());
  return gt_.empty() ? std::nullopt : gt_[index];
}

OrganizedCloud ReadOrganizedPcd(const std::string& path, const SensorConfig& config) {
  const SensorModel model =
      config.pcd_model == "spherical" ? SensorModel::kSpherical : SensorModel::kPinhole;
  OrganizedCloud cloud = ReadPcd(path, config.unit_scale, model);
  if (cloud.height <= 1) {
    throw IoError(path, "cloud is not organized (HEIGHT " + std::to_string(cloud.height) +
                            "); planeslam needs a range-image grid");
  }
  ApplyRangeLimits(&cloud, config.min_depth, config.max_depth);
  return cloud;
}

std::unique_ptr<FileSequence> OpenPcdFolder(const std::string& folder, const SensorConfig& config) {
  config.ValidateOrThrow();
  auto files = ListFrameFiles(folder, ".pcd");
  if (files.empty()) throw IoError(folder, "no .pcd files in folder");
  fs::path p = fs::path(folder).lexically_normal();
  if (p.filename().empty()) p = p.parent_path();
  // Ground truth beside the scans (TUM format, as `planeslam simulate --sensor spherical` writes
  // it), matched to the stamps in the file names like TUM's associate.py.
  std::vector<double> stamps = StampsFromFileNames(files);
  std::vector<std::optional<Pose>> gt;
  const fs::path gt_path = p / "groundtruth.txt";
  std::error_code ec;
  if (fs::is_regular_file(gt_path, ec)) {
    gt =
        AssociateByTime(stamps, ReadTumTrajectory(gt_path.string()), config.gt_max_time_difference);
  }
  return std::make_unique<FileSequence>(
      p.filename().string(), std::move(files),
      [config](const std::string& path) { return ReadOrganizedPcd(path, config); }, std::move(gt),
      std::move(stamps));
}

}  // namespace planeslam::datasets
