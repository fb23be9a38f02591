#pragma once
/// Config sections of the synthetic generator ("simulation", "simulation_pinhole",
/// "simulation_spherical") and the factory `planeslam simulate` and `planeslam run` (with no
/// sequence) use.
#include <memory>
#include <string>

#include "config.hpp"
#include "planeslam/datasets/synthetic_sequence.hpp"

namespace planeslam::app {

/// YAML section "simulation": the scene, the sensor and the camera path. Sections
/// "simulation_pinhole", "simulation_spherical" and "simulation_lidar" hold the sensors.
struct SimulationConfig {
  std::string scene = "room";      ///< room, corridor, rubble or street (`planeslam run` default)
  int seed = 1;                    ///< rubble and street layouts and sensor noise [1]
  std::string sensor = "auto";     ///< pinhole, spherical, lidar or auto (the scene's default)
  bool noise = true;               ///< sensor noise on (off: exact ranges)
  int frames = 0;                  ///< number of frames; 0 = the scene's path (laps or length)
  double rate = 0.0;               ///< frame rate [Hz]; 0 = scene default (30, street 10)
  double speed = 0.0;              ///< along the path [m/s]; 0 = scene default
  double laps = 0.0;               ///< loop scenes: turns when frames = 0 [1]; 0 = default
  double length = 0.0;             ///< corridor: run length when frames = 0 [m]; 0 = default
};

/// The datasets-level config for `scene` ("" = simulation.scene) from the three sections.
datasets::SyntheticConfig MakeSyntheticConfig(const std::string& scene, const Config& config);

/// The in-memory synthetic sequence for `scene` ("" = simulation.scene). Throws ConfigError.
std::unique_ptr<datasets::SyntheticSequence> MakeSyntheticSequence(const std::string& scene,
                                                                   const Config& config);

}  // namespace planeslam::app
