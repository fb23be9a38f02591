#pragma once
/// Shared pieces of `planeslam bench`: the benchmark frames, the methods (our detectors and the PCL
/// baseline) and how one detection is timed.
#include <memory>
#include <string>
#include <vector>

#include "config.hpp"
#include "planeslam/datasets/organized_cloud.hpp"
#include "planeslam/datasets/sensor_config.hpp"
#include "planeslam/detection/plane.hpp"
#include "planeslam/detection/plane_detector.hpp"

namespace planeslam::app::bench {

/// The shared data folder: $PLANESLAM_DATA_DIR, else ../shared/data relative to the working
/// directory (the same rule as the tests).
std::string DataDir();

/// One benchmark frame.
struct BenchFrame {
  std::string name;  ///< short, e.g. "tum_fr3_structure_notexture_far/000050" or "office1"
  datasets::OrganizedCloud cloud;
};

/// The default frame set under `data_dir`: every 50th frame of tum_fr3_structure_notexture_far,
/// organized_pcd/office1, table_scene_mug_stereo_textured and the three frame_*.pcd (Kinect),
/// and the three laser scans (centimetres, spherical grid). Missing files are skipped and named in
/// `skipped`. `sensor` supplies depth intrinsics and range limits. Frames are read on the
/// machine's cores, in the order above.
std::vector<BenchFrame> LoadDefaultFrames(const std::string& data_dir,
                                          const datasets::SensorConfig& sensor,
                                          std::vector<std::string>* skipped);

/// Frames from the command line: a file is one frame (LoadSingleFrame); a folder is a sequence of
/// which every `stride`-th frame is used, read on the machine's cores. Throws IoError for
/// unreadable input (the first unreadable frame in order).
std::vector<BenchFrame> LoadFrames(const std::vector<std::string>& paths,
                                   const datasets::SensorConfig& sensor, int stride);

/// Settings of the PCL baseline given on the command line (mirrors pcl_baselines::OmpsConfig so
/// that this header stays free of the PCL-only library).
struct OmpsSettings {
  std::string normal_method = "covariance";
  double max_depth_change_factor = 0.02;
  double normal_smoothing_size = 10.0;
  int min_inliers = 400;
  double angular_threshold_deg = 5.0;
  double distance_threshold = 0.02;
  double maximum_curvature = 0.01;
  /// One line for reports.
  std::string Describe() const;
};

/// A method under test.
struct Method {
  std::string name;
  std::unique_ptr<detection::PlaneDetector> detector;
  bool is_pcl = false;  ///< time only PCL's own stages (normals + segment), see TimedDetect
};

/// "pcl_omps" when the PCL baselines are built, else nothing.
std::vector<std::string> BaselineMethods();
/// Our detectors' names (from the detector factory) followed by BaselineMethods().
std::vector<std::string> AllMethods();
/// Builds the named methods. Throws ConfigError naming an unknown method.
std::vector<Method> MakeMethods(const std::vector<std::string>& names, const Config& config,
                                const OmpsSettings& omps);

/// Runs one detection. Returns the time [ms]: wall time of Detect() for our detectors; for the
/// PCL baseline only its "normals" + "segment" stages (conversion from/to our types excluded), so
/// any speed ratio against PCL is conservative.
double TimedDetect(const Method& method, const datasets::OrganizedCloud& cloud,
                   detection::Segmentation* segmentation);

/// Fraction of valid points carrying a plane label.
double AssignedFraction(const datasets::OrganizedCloud& cloud,
                        const detection::Segmentation& segmentation);

/// Median (mean of the two middle values for an even count); NaN when empty.
double Median(std::vector<double> values);

/// Comma-separated list -> items (empty items dropped).
std::vector<std::string> SplitList(const std::string& text);

}  // namespace planeslam::app::bench
