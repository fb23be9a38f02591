#pragma once
/// Sensor profiles: the config files in config/ that suit one kind of data, chosen from the data
/// itself (layout, folder name, intrinsics, image size) or by name with --sensor. A profile's files
/// apply as if given with -c before the user's own -c files, so -c and --set still override them.
#include <CLI/CLI.hpp>
#include <map>
#include <string>
#include <vector>

#include "cli_common.hpp"
#include "config.hpp"
#include "planeslam/datasets/sensor_config.hpp"

namespace planeslam::app {

/// One profile: the config files it applies, in order, and what it amounts to.
struct SensorProfile {
  std::string name;                ///< for --sensor
  std::vector<std::string> files;  ///< "config/<file>.yaml", compiled in
  std::string summary;             ///< e.g. "Kinect profile, half resolution"
  bool depth_camera = false;       ///< its sensor section is a pinhole depth camera's
};

/// The profile chosen for an input and why; `profile` is null when none applies.
struct ProfileChoice {
  const SensorProfile* profile = nullptr;
  std::string reason;  ///< what was recognised, e.g. "TUM RGB-D fr3 layout"
};

/// Every profile, in the order --help lists them.
const std::vector<SensorProfile>& SensorProfiles();

/// The text of every config/*.yaml of the source tree by "config/<name>" (generated at build time).
const std::map<std::string, std::string>& ConfigFiles();

/// What `input` (a sequence folder or a single frame file) looks like. Never throws for an input
/// it cannot recognise (the reader then reports the problem): the choice is empty with a reason.
ProfileChoice RecognizeInput(const std::string& input);

/// The --sensor option: a profile name, "none", or empty (recognise the input).
ProfileChoice ChooseProfile(const std::string& sensor_option, const std::string& input);

/// Adds --sensor NAME to `sub`.
void AddSensorOption(CLI::App& sub, std::string& sensor);

/// Applies the chosen profile's files to `config` and prints one line on stderr saying what was
/// chosen and why.
void ApplyProfile(const ProfileChoice& choice, const std::string& command, Config* config);

/// LoadConfig with the profile of `input` (or of --sensor `sensor`) applied before the -c files;
/// the choice is stored in `chosen` when given.
Config LoadConfigWithProfile(const ConfigOptions& options, const std::string& sensor,
                             const std::string& input, const std::string& command,
                             ProfileChoice* chosen = nullptr);

/// LoadConfigWithProfile for `planeslam run` without a sequence: the built-in scene (`scene`, or
/// the config's simulation.scene) gets the profile its `planeslam simulate` output would get when
/// its simulated sensor is a LiDAR (the kitti profile); a depth-camera scene keeps the defaults,
/// which are tuned on it. --sensor still decides when given.
Config LoadConfigForScene(const ConfigOptions& options, const std::string& sensor,
                          const std::string& scene, const std::string& command);

/// The camera a single depth PNG is read with, in this order: the --intrinsics file; an
/// intrinsics.yaml beside the image; the profile chosen for it (its dataset folder's
/// intrinsics.yaml when the folder has one, else the profile's sensor section); a sensor section
/// the user's -c or --set changed; the one profile whose camera has the image's size. Sets
/// `sensor`'s camera keys and returns where they came from; throws IoError naming the image and
/// the option to give when none of these tells.
std::string ResolveDepthCamera(const std::string& png, const std::string& intrinsics_option,
                               const ProfileChoice& profile, datasets::SensorConfig* sensor);

}  // namespace planeslam::app
