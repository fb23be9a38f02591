#include "bench_common.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <limits>
#include <memory>
#include <sstream>

#include "detector_factory.hpp"
#include "pipeline.hpp"
#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/file_sequence.hpp"
#include "planeslam/datasets/sequence.hpp"
#include "planeslam/datasets/sequence_factory.hpp"
#ifdef PLANESLAM_HAVE_PCL_BASELINES
#include "pcl/baselines.hpp"
#endif

namespace planeslam::app::bench {
namespace fs = std::filesystem;

std::string DataDir() {
  if (const char* env = std::getenv("PLANESLAM_DATA_DIR"); env && *env) return env;
  return "../shared/data";
}

namespace {

std::string Padded(std::size_t index) {
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%06zu", index);
  return buffer;
}

/// Frames to load, in order: each job reads one frame. Reading is independent per frame, so the
/// jobs run on the machine's cores; the result keeps their order.
using FrameJobs = std::vector<std::function<BenchFrame()>>;

std::vector<BenchFrame> RunJobs(const FrameJobs& jobs) {
  std::vector<BenchFrame> frames(jobs.size());
  ParallelFor(jobs.size(), ResolveThreads(0), [&](std::size_t i) { frames[i] = jobs[i](); });
  return frames;
}

void AddSequenceFrames(const std::string& folder, const datasets::SensorConfig& sensor,
                       int stride, FrameJobs* jobs) {
  std::shared_ptr<const datasets::Sequence> sequence = datasets::OpenSequence(folder, sensor);
  const std::string name = fs::path(folder).filename().empty()
                               ? fs::path(folder).parent_path().filename().string()
                               : fs::path(folder).filename().string();
  for (std::size_t i = 0; i < sequence->Size(); i += static_cast<std::size_t>(stride)) {
    jobs->push_back([sequence, i, name] {
      return BenchFrame{name + "/" + Padded(i), sequence->Load(i).cloud};
    });
  }
}

}  // namespace

std::vector<BenchFrame> LoadDefaultFrames(const std::string& data_dir,
                                          const datasets::SensorConfig& sensor,
                                          std::vector<std::string>* skipped) {
  FrameJobs jobs;
  const fs::path root(data_dir);
  const fs::path tum = root / "tum_fr3_structure_notexture_far";
  if (fs::is_directory(tum)) {
    AddSequenceFrames(tum.string(), sensor, 50, &jobs);
  } else if (skipped) {
    skipped->push_back(tum.string());
  }
  // Kinect clouds from PCL's test data (metres, pinhole grid).
  datasets::SensorConfig kinect = sensor;
  kinect.unit_scale = 1.0;
  kinect.pcd_model = "pinhole";
  std::vector<fs::path> kinect_files = {root / "organized_pcd" / "office1.pcd",
                                        root / "organized_pcd" / "table_scene_mug_stereo_textured.pcd"};
  if (fs::is_directory(root / "organized_pcd")) {
    std::vector<fs::path> sequence;
    for (const auto& entry : fs::directory_iterator(root / "organized_pcd")) {
      const std::string file = entry.path().filename().string();
      if (file.rfind("frame_", 0) == 0 && entry.path().extension() == ".pcd") {
        sequence.push_back(entry.path());
      }
    }
    std::sort(sequence.begin(), sequence.end());
    kinect_files.insert(kinect_files.end(), sequence.begin(), sequence.end());
  }
  for (const fs::path& file : kinect_files) {
    if (!fs::is_regular_file(file)) {
      if (skipped) skipped->push_back(file.string());
      continue;
    }
    jobs.push_back([file, kinect] {
      return BenchFrame{file.stem().string(), datasets::ReadOrganizedPcd(file.string(), kinect)};
    });
  }
  // Terrestrial laser scans: coordinates in centimetres, rows = elevation, columns = azimuth.
  datasets::SensorConfig laser;
  laser.unit_scale = 0.01;
  laser.pcd_model = "spherical";
  for (const char* scan : {"scan000.pcd", "scan001.pcd", "scan002.pcd"}) {
    const fs::path file = root / "laser_scans" / scan;
    if (!fs::is_regular_file(file)) {
      if (skipped) skipped->push_back(file.string());
      continue;
    }
    jobs.push_back([file, laser] {
      return BenchFrame{"laser_" + file.stem().string(),
                        datasets::ReadOrganizedPcd(file.string(), laser)};
    });
  }
  return RunJobs(jobs);
}

std::vector<BenchFrame> LoadFrames(const std::vector<std::string>& paths,
                                   const datasets::SensorConfig& sensor, int stride) {
  PLANESLAM_CHECK(stride >= 1, "stride " << stride);
  FrameJobs jobs;
  for (const std::string& path : paths) {
    if (fs::is_directory(path)) {
      AddSequenceFrames(path, sensor, stride, &jobs);
    } else {
      jobs.push_back([path, sensor] {
        return BenchFrame{fs::path(path).stem().string(),
                          datasets::LoadSingleFrame(path, sensor).cloud};
      });
    }
  }
  return RunJobs(jobs);
}

std::string OmpsSettings::Describe() const {
  std::ostringstream os;
  os << "normals=" << normal_method << " max_depth_change_factor=" << max_depth_change_factor
     << " normal_smoothing_size=" << normal_smoothing_size << " min_inliers=" << min_inliers
     << " angular_threshold=" << angular_threshold_deg << "deg distance_threshold="
     << distance_threshold << "m(*z^2) maximum_curvature=" << maximum_curvature;
  return os.str();
}

std::vector<std::string> BaselineMethods() {
#ifdef PLANESLAM_HAVE_PCL_BASELINES
  return {"pcl_omps"};
#else
  return {};
#endif
}

std::vector<std::string> AllMethods() {
  std::vector<std::string> names = DetectorMethods();
  for (const std::string& b : BaselineMethods()) names.push_back(b);
  return names;
}

std::vector<Method> MakeMethods(const std::vector<std::string>& names, const Config& config,
                                const OmpsSettings& omps) {
  std::vector<Method> methods;
  const std::vector<std::string> ours = DetectorMethods();
  for (const std::string& name : names) {
    Method m;
    m.name = name;
    if (std::find(ours.begin(), ours.end(), name) != ours.end()) {
      m.detector = MakeDetector(name, config);
#ifdef PLANESLAM_HAVE_PCL_BASELINES
    } else if (name == "pcl_omps") {
      pcl_baselines::OmpsConfig c;
      c.normal_method = omps.normal_method;
      c.max_depth_change_factor = omps.max_depth_change_factor;
      c.normal_smoothing_size = omps.normal_smoothing_size;
      c.min_inliers = omps.min_inliers;
      c.angular_threshold_deg = omps.angular_threshold_deg;
      c.distance_threshold = omps.distance_threshold;
      c.maximum_curvature = omps.maximum_curvature;
      if (c.normal_method != "covariance" && c.normal_method != "average_3d_gradient") {
        throw ConfigError("--omps-normals: '" + c.normal_method +
                          "' is not covariance or average_3d_gradient");
      }
      m.detector = std::make_unique<pcl_baselines::OmpsDetector>(c);
      m.is_pcl = true;
#endif
    } else {
      std::string known;
      for (const std::string& k : AllMethods()) known += (known.empty() ? "" : ", ") + k;
      throw ConfigError("unknown method '" + name + "' (known: " + known + ")");
    }
    methods.push_back(std::move(m));
  }
  return methods;
}

double TimedDetect(const Method& method, const datasets::OrganizedCloud& cloud,
                   detection::Segmentation* segmentation) {
  const auto start = std::chrono::steady_clock::now();
  *segmentation = method.detector->Detect(cloud);
  const double wall =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  if (!method.is_pcl) return wall;
  double core = 0.0;
  bool found = false;
  for (const auto& [stage, ms] : segmentation->timings_ms) {
    if (stage == "normals" || stage == "segment") {
      core += ms;
      found = true;
    }
  }
  return found ? core : wall;
}

double AssignedFraction(const datasets::OrganizedCloud& cloud,
                        const detection::Segmentation& segmentation) {
  std::size_t valid = 0, assigned = 0;
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    if (!cloud.IsValid(i)) continue;
    ++valid;
    if (i < segmentation.labels.size() && segmentation.labels[i] > 0) ++assigned;
  }
  return valid ? double(assigned) / valid : 0.0;
}

double Median(std::vector<double> values) {
  if (values.empty()) return std::numeric_limits<double>::quiet_NaN();
  std::sort(values.begin(), values.end());
  const std::size_t n = values.size();
  return n % 2 ? values[n / 2] : 0.5 * (values[n / 2 - 1] + values[n / 2]);
}

std::vector<std::string> SplitList(const std::string& text) {
  std::vector<std::string> items;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) {
    item.erase(0, item.find_first_not_of(" \t"));
    item.erase(item.find_last_not_of(" \t") + 1);
    if (!item.empty()) items.push_back(item);
  }
  return items;
}

}  // namespace planeslam::app::bench
