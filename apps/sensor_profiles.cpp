#include "sensor_profiles.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <iostream>
#include <optional>

#include "config_sections_synthetic.hpp"
#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/image_io.hpp"
#include "planeslam/datasets/pcd_io.hpp"
#include "planeslam/datasets/sensor_config.hpp"
#include "planeslam/datasets/sequence_factory.hpp"

namespace planeslam::app {
namespace {

namespace fs = std::filesystem;
namespace ds = planeslam::datasets;

const SensorProfile* FindProfile(const std::string& name) {
  for (const SensorProfile& p : SensorProfiles()) {
    if (p.name == name) return &p;
  }
  return nullptr;
}

ProfileChoice Choice(const std::string& profile, std::string reason) {
  return {FindProfile(profile), std::move(reason)};
}

std::string Lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return s;
}

/// The folder's own name (without a trailing slash).
std::string FolderName(const fs::path& folder) {
  fs::path p = folder.lexically_normal();
  if (p.filename().empty()) p = p.parent_path();
  return p.filename().string();
}

/// TUM RGB-D's depth cameras: fr1 and fr2 were calibrated Kinects of their own, fr3's depth is
/// factory-registered. Told apart by the folder name (freiburgN / frN), else by the focal length
/// of the folder's intrinsics.yaml; fr3 otherwise.
ProfileChoice RecognizeTum(const fs::path& folder) {
  const std::string name = Lower(FolderName(folder));
  for (const char* fr : {"1", "2", "3"}) {
    if (name.find(std::string("freiburg") + fr) != std::string::npos ||
        name.find(std::string("fr") + fr) != std::string::npos) {
      return Choice(std::string("tum-fr") + fr, std::string("TUM RGB-D fr") + fr +
                                                    " layout (depth.txt; fr" + fr +
                                                    " from the folder name)");
    }
  }
  std::error_code ec;
  if (fs::is_regular_file(folder / "intrinsics.yaml", ec)) {
    try {
      const double fx = ds::ReadCameraFile((folder / "intrinsics.yaml").string()).intrinsics.fx;
      const std::pair<const char*, double> focal[] = {{"1", 517.3}, {"2", 520.9}, {"3", 535.4}};
      for (const auto& [fr, f] : focal) {
        if (std::abs(fx - f) < 1.0) {
          return Choice(std::string("tum-fr") + fr, std::string("TUM RGB-D fr") + fr +
                                                        " layout (depth.txt; fr" + fr +
                                                        " from intrinsics.yaml's fx)");
        }
      }
    } catch (const IoError&) {
      // The reader reports a bad intrinsics.yaml when it opens the sequence.
    }
  }
  return Choice("tum-fr3", "TUM RGB-D layout (depth.txt; no fr1/fr2 hint, fr3 assumed)");
}

/// The sensor a simulated scene is seen by: `sensor`, or for "auto" the scene's own (the street's
/// rotating LiDAR, a depth camera elsewhere).
std::string SimulatedSensor(const std::string& scene, const std::string& sensor) {
  if (sensor != "auto") return sensor;
  return scene == "street" ? "lidar" : "pinhole";
}

/// The outputs of `planeslam simulate`: its config.yaml has a simulation section.
std::optional<ProfileChoice> RecognizeSimulation(const fs::path& folder) {
  std::error_code ec;
  if (!fs::is_regular_file(folder / "config.yaml", ec)) return std::nullopt;
  try {
    const YAML::Node root = YAML::LoadFile((folder / "config.yaml").string());
    const YAML::Node sim = root["simulation"];
    if (!sim || !sim.IsMap()) return std::nullopt;
    const std::string scene = sim["scene"] ? sim["scene"].as<std::string>() : "?";
    const std::string sensor =
        SimulatedSensor(scene, sim["sensor"] ? sim["sensor"].as<std::string>() : "auto");
    const std::string why =
        "planeslam simulate output (config.yaml: scene " + scene + ", " + sensor + " sensor)";
    if (sensor == "pinhole") return Choice("synthetic", why);
    // The simulated rotating LiDAR writes the KITTI layout with the HDL-64E's geometry.
    if (sensor == "lidar") return Choice("kitti", why + ", KITTI layout");
    return ProfileChoice{nullptr, why + ", no profile for the simulated scanner"};
  } catch (const YAML::Exception&) {
    return std::nullopt;
  }
}

/// Depth-camera image sizes; an organized cloud of another size is taken for a laser scan.
bool IsCameraSize(std::int64_t width, std::int64_t height) {
  const std::pair<int, int> sizes[] = {{640, 480}, {320, 240},  {160, 120}, {1280, 720},
                                       {512, 424}, {1280, 960}, {848, 480}};
  for (const auto& [w, h] : sizes) {
    if (width == w && height == h) return true;
  }
  return false;
}

/// An organized PCD from a laser (not a depth camera's image size) in centimetres gets the laser
/// profile; the median range decides the unit (a scan of rooms and houses in metres has a median
/// range of metres, in centimetres of hundreds).
ProfileChoice RecognizePcd(const fs::path& pcd) {
  try {
    const ds::OrganizedCloud cloud = ds::ReadPcd(pcd.string());
    const std::string size = std::to_string(cloud.width) + "x" + std::to_string(cloud.height);
    if (cloud.height <= 1) return {nullptr, "unorganized PCD: no profile"};
    if (IsCameraSize(cloud.width, cloud.height)) {
      return {nullptr, "organized PCD " + size + " (a depth camera's size): no profile"};
    }
    std::vector<float> ranges;
    for (std::size_t i = 0; i < cloud.size(); ++i) {
      if (cloud.IsValid(i)) ranges.push_back(cloud.points[i].norm());
    }
    if (ranges.empty()) return {nullptr, "PCD without valid points: no profile"};
    std::nth_element(ranges.begin(), ranges.begin() + ranges.size() / 2, ranges.end());
    const float median = ranges[ranges.size() / 2];
    if (median < 100.0f) {
      return {nullptr, "organized laser PCD " + size +
                           " in metres: no profile (laser uses centimetre PCDs)"};
    }
    return Choice("laser", "organized laser PCD " + size + ", median range " +
                               std::to_string(static_cast<int>(median)) + " (centimetres)");
  } catch (const IoError&) {
    return {nullptr, "unreadable PCD: no profile"};
  }
}

/// The first file of `folder` with extension `ext` in name order.
fs::path FirstWithExtension(const fs::path& folder, const std::string& ext) {
  std::vector<fs::path> files;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(folder, ec)) {
    if (entry.is_regular_file(ec) && Lower(entry.path().extension().string()) == ext) {
      files.push_back(entry.path());
    }
  }
  return files.empty() ? fs::path() : *std::min_element(files.begin(), files.end());
}

/// The folder holding the image's folder (the dataset folder of depth/NAME.png); "." for an image
/// given as depth/NAME.png from inside the dataset folder.
fs::path DatasetFolderOf(const fs::path& image) {
  const fs::path folder = image.parent_path();
  return folder.has_parent_path() ? folder.parent_path() : fs::path(".");
}

ProfileChoice RecognizeFolder(const fs::path& folder) {
  if (auto sim = RecognizeSimulation(folder)) return *sim;
  ds::SequenceLayout layout;
  try {
    layout = ds::DetectLayout(folder.string());
  } catch (const IoError&) {
    return {nullptr, "no known layout"};
  }
  switch (layout) {
    case ds::SequenceLayout::kTum:
      return RecognizeTum(folder);
    case ds::SequenceLayout::kIclNuim:
      return Choice("icl-nuim", "ICL-NUIM layout (associations.txt)");
    case ds::SequenceLayout::kKittiBin:
      return Choice("kitti", "KITTI Velodyne layout (.bin scans or velodyne/)");
    case ds::SequenceLayout::kPcdFolder:
      return RecognizePcd(FirstWithExtension(folder, ".pcd"));
  }
  return {nullptr, "no known layout"};
}

/// A depth PNG: the dataset folder it sits in (TUM's depth/ beside depth.txt, ICL's beside
/// associations.txt); otherwise the one profile whose camera has the image's size, if only one.
ProfileChoice RecognizePng(const fs::path& png) {
  const fs::path dataset = DatasetFolderOf(png);
  std::error_code ec;
  if (png.parent_path().filename() == "depth") {
    if (fs::is_regular_file(dataset / "depth.txt", ec) ||
        fs::is_regular_file(dataset / "associations.txt", ec)) {
      ProfileChoice choice = RecognizeFolder(dataset);
      choice.reason = "image of a dataset folder: " + choice.reason;
      return choice;
    }
  }
  return {nullptr, "depth PNG outside a known dataset folder"};
}

}  // namespace

const std::vector<SensorProfile>& SensorProfiles() {
  static const std::vector<SensorProfile> profiles = {
      {"tum-fr3",
       {"config/tum_fr3.yaml", "config/detection_kinect.yaml"},
       "Kinect profile, half resolution",
       true},
      {"tum-fr1",
       {"config/tum_fr3.yaml", "config/tum_fr1.yaml", "config/detection_kinect.yaml"},
       "Kinect profile with fr1 intrinsics, half resolution",
       true},
      {"tum-fr2",
       {"config/tum_fr3.yaml", "config/tum_fr2.yaml", "config/detection_kinect.yaml"},
       "Kinect profile with fr2 intrinsics, half resolution",
       true},
      {"icl-nuim",
       {"config/icl_nuim.yaml", "config/detection_kinect.yaml"},
       "ICL-NUIM camera, Kinect detection profile",
       true},
      {"kitti", {"config/kitti_hdl64.yaml"}, "HDL-64E range image"},
      {"laser",
       {"config/laser_scan.yaml", "config/detection_laser.yaml"},
       "terrestrial laser profile, centimetre PCDs"},
      {"synthetic", {"config/detection_synthetic.yaml"}, "simulator's detection profile"},
  };
  return profiles;
}

ProfileChoice RecognizeInput(const std::string& input) {
  if (input.empty()) return {nullptr, "no input"};
  const fs::path path(input);
  std::error_code ec;
  if (fs::is_directory(path, ec)) return RecognizeFolder(path);
  if (!fs::is_regular_file(path, ec)) return {nullptr, "no such file or folder"};
  const std::string ext = Lower(path.extension().string());
  if (ext == ".bin") return Choice("kitti", "KITTI Velodyne scan (.bin)");
  if (ext == ".pcd") return RecognizePcd(path);
  if (ext == ".png") return RecognizePng(path);
  return {nullptr, "unknown file type"};
}

ProfileChoice ChooseProfile(const std::string& sensor_option, const std::string& input) {
  if (sensor_option.empty()) return RecognizeInput(input);
  if (sensor_option == "none") return {nullptr, "--sensor none"};
  const SensorProfile* profile = FindProfile(sensor_option);
  if (profile == nullptr) {
    std::string names;
    for (const SensorProfile& p : SensorProfiles()) names += " " + p.name;
    throw ConfigError("--sensor: unknown profile '" + sensor_option + "' (one of:" + names +
                      ", none)");
  }
  return {profile, "--sensor " + sensor_option};
}

void AddSensorOption(CLI::App& sub, std::string& sensor) {
  std::string names;
  for (const SensorProfile& p : SensorProfiles()) names += p.name + ", ";
  sub.add_option("--sensor", sensor,
                 "sensor profile (config files applied before -c): " + names +
                     "none; default: recognised from the input")
      ->type_name("NAME");
}

void ApplyProfile(const ProfileChoice& choice, const std::string& command, Config* config) {
  if (choice.profile == nullptr) {
    std::cerr << "planeslam " << command << ": no sensor profile (" << choice.reason
              << "): the defaults and -c files only\n";
    return;
  }
  std::string files;
  for (const std::string& file : choice.profile->files) {
    const auto it = ConfigFiles().find(file);
    PLANESLAM_CHECK(it != ConfigFiles().end(), "profile file " << file << " not compiled in");
    config->LoadString(it->second, file);
    files += (files.empty() ? "" : ", ") + file;
  }
  std::cerr << "planeslam " << command << ": " << choice.reason << ": " << choice.profile->summary
            << " (--sensor " << choice.profile->name << ": " << files << ")\n";
}

namespace {

/// The profile of `choice` (none when null), then the -c files and --set on top.
Config LoadWithChoice(const ConfigOptions& options, const ProfileChoice* choice,
                      const std::string& command) {
  Config config;
  if (choice != nullptr) ApplyProfile(*choice, command, &config);
  for (const auto& file : options.config_files) config.LoadFile(file);
  for (const auto& assignment : options.overrides) config.Set(assignment);
  return config;
}

}  // namespace

Config LoadConfigWithProfile(const ConfigOptions& options, const std::string& sensor,
                             const std::string& input, const std::string& command,
                             ProfileChoice* chosen) {
  if (input.empty() && sensor.empty()) return LoadWithChoice(options, nullptr, command);
  const ProfileChoice choice = ChooseProfile(sensor, input);
  if (chosen != nullptr) *chosen = choice;
  return LoadWithChoice(options, &choice, command);
}

Config LoadConfigForScene(const ConfigOptions& options, const std::string& sensor,
                          const std::string& scene, const std::string& command) {
  if (!sensor.empty()) return LoadConfigWithProfile(options, sensor, "", command);
  // The scene and its sensor as the -c files and --set leave them.
  Config config = LoadWithChoice(options, nullptr, command);
  const SimulationConfig& sim = config.Get<SimulationConfig>("simulation");
  const std::string name = scene.empty() ? sim.scene : scene;
  if (SimulatedSensor(name, sim.sensor) != "lidar") return config;
  const ProfileChoice choice = Choice("kitti", "built-in scene " + name + ", simulated LiDAR");
  return LoadWithChoice(options, &choice, command);
}

std::string ResolveDepthCamera(const std::string& png, const std::string& intrinsics_option,
                               const ProfileChoice& profile, datasets::SensorConfig* sensor) {
  const fs::path path(png);
  fs::path file = intrinsics_option;
  std::string source = intrinsics_option + " (--intrinsics)";
  std::error_code ec;
  const fs::path dataset = DatasetFolderOf(path);
  if (file.empty() && fs::is_regular_file(path.parent_path() / "intrinsics.yaml", ec)) {
    file = path.parent_path() / "intrinsics.yaml";
    source = file.string() + " (beside the image)";
  } else if (file.empty() && profile.profile != nullptr && sensor->intrinsics_source == "auto" &&
             fs::is_regular_file(dataset / "intrinsics.yaml", ec)) {
    file = dataset / "intrinsics.yaml";
    source = file.string() + " (the image's dataset folder)";
  }
  if (!file.empty()) {
    const ds::CameraFile camera = ds::ReadCameraFile(file.string());
    sensor->intrinsics = camera.intrinsics;
    sensor->depth_scale = camera.depth_scale;
    sensor->flip_y = false;  // the file's intrinsics already carry the flip (fy < 0)
    sensor->intrinsics_source = "config";
    return source;
  }
  if (profile.profile != nullptr) {
    return "the sensor section (--sensor " + profile.profile->name + ", then -c and --set)";
  }
  const ds::SensorConfig defaults;
  const ds::PinholeIntrinsics& k = sensor->intrinsics;
  const ds::PinholeIntrinsics& d = defaults.intrinsics;
  if (k.width != d.width || k.height != d.height || k.fx != d.fx || k.fy != d.fy || k.cx != d.cx ||
      k.cy != d.cy || sensor->depth_scale != defaults.depth_scale ||
      sensor->flip_y != defaults.flip_y) {
    return "the sensor section (-c/--set)";
  }
  // Nothing names the camera: only the image's size and encoding are left.
  const ds::Image16 image = ds::ReadPng16(png);
  std::vector<const SensorProfile*> fits;
  for (const SensorProfile& p : SensorProfiles()) {
    Config config;
    for (const std::string& f : p.files) config.LoadString(ConfigFiles().at(f), f);
    const auto& camera = config.Get<ds::SensorConfig>("sensor").intrinsics;
    if (p.depth_camera && camera.width == image.width && camera.height == image.height) {
      fits.push_back(&p);
    }
  }
  const std::string size = std::to_string(image.width) + "x" + std::to_string(image.height);
  if (fits.size() == 1) {
    Config config;
    for (const std::string& f : fits.front()->files) config.LoadString(ConfigFiles().at(f), f);
    *sensor = config.Get<ds::SensorConfig>("sensor");
    return "--sensor " + fits.front()->name + " (the only camera with " + size + " depth images)";
  }
  std::string names;
  for (const SensorProfile* p : fits) names += (names.empty() ? "" : ", ") + p->name;
  throw IoError(png, "cannot tell which camera took this " + size + " 16-bit depth image" +
                         (fits.empty() ? "" : " (" + names + " all fit)") +
                         ": give --intrinsics FILE (or --sensor NAME)");
}

}  // namespace planeslam::app
