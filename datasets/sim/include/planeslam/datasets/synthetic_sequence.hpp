#pragma once
/// Synthetic sequences: a scene, a smooth trajectory through it and a simulated sensor, generated
/// on demand in memory (no files) with exact ground truth: poses, per-pixel plane labels and the
/// world planes.
///
/// Determinism: frame i depends only on the config and i (its noise is seeded by
/// MixSeed(seed, i)), so frames can be loaded in any order, and the same config gives the same
/// bytes. Random numbers come from std::mt19937_64 (fixed by the standard) with our own
/// uniform/normal transforms, so they do not depend on the standard library's distributions.
#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "planeslam/datasets/sequence.hpp"
#include "planeslam/datasets/synthetic_lidar.hpp"
#include "planeslam/datasets/synthetic_scene.hpp"
#include "planeslam/datasets/synthetic_sensor.hpp"

namespace planeslam::datasets {

/// Smooth camera path. "loop": circles `laps` times around `center` at `radius`, so it passes its
/// start again (a loop closure); "line": a straight run along +x from `start`; "street": the car's
/// route around the street scene's central block (synthetic_street.hpp: `speed` on the straights,
/// `laps`, and the pitch, roll and height amplitudes as its suspension motion).
/// Values of 0 for speed/radius/height mean "the scene's default" (see DefaultTrajectory()).
struct SyntheticTrajectoryConfig {
  std::string kind = "loop";  ///< "loop", "line" or "street"
  int frames = 0;             ///< number of frames; 0 = enough for `laps` laps (or `length`)
  double rate = 30.0;         ///< frame rate [Hz]
  double speed = 0.4;         ///< along the path [m/s]
  double laps = 1.5;          ///< loop: turns around the centre when frames = 0 [1]
  double length = 10.0;       ///< line: run length when frames = 0 [m]
  Eigen::Vector3d center = Eigen::Vector3d(0, 0, 1.4);  ///< loop centre / line start [m]
  double radius = 0.8;                 ///< loop radius [m]
  /// Loop: angular position of the start around the centre (0 = +x side) [deg]. The room starts
  /// facing the corner with the table.
  double start_angle_deg = 135.0;
  double height_amplitude = 0.15;      ///< sinusoidal height change [m]
  double lateral_amplitude = 0.15;     ///< line: sideways sway [m]
  std::string look = "outward";        ///< loop: "outward", "inward" or "forward" (tangent)
  double pitch_deg = -10.0;            ///< mean pitch (negative = down) [deg]
  double pitch_amplitude_deg = 8.0;    ///< [deg]
  double yaw_amplitude_deg = 20.0;     ///< looking left and right around the heading [deg]
  double roll_amplitude_deg = 3.0;     ///< [deg]
};

/// The default path of each scene (room: outward-looking loop at r 0.8 m; corridor: straight run;
/// rubble: inward-looking loop at r 3.8 m around the pile; street: 1.15 laps around the block at
/// 10 m/s, 10 Hz).
SyntheticTrajectoryConfig DefaultTrajectory(SceneKind kind);

/// Number of frames the config asks for (resolves frames = 0).
int TrajectoryFrameCount(const SyntheticTrajectoryConfig& config);

/// Body pose (forward-left-up, z up) at time t [s].
Pose TrajectoryBodyPose(const SyntheticTrajectoryConfig& config, double t);

/// Everything that defines a synthetic sequence.
struct SyntheticConfig {
  SceneKind scene = SceneKind::kRoom;
  std::uint64_t seed = 1;         ///< rubble layout and sensor noise
  std::string sensor = "pinhole";  ///< "pinhole", "spherical" or "lidar" (rotating, KITTI layout)
  PinholeSimConfig pinhole;
  SphericalSimConfig spherical;
  LidarSimConfig lidar;
  SyntheticTrajectoryConfig trajectory;

  /// Defaults for `scene` (its trajectory and sensor: lidar for the street, else pinhole).
  static SyntheticConfig ForScene(SceneKind scene);
};

/// A frame with its label image.
struct SyntheticFrame {
  Frame frame;    ///< cloud (sensor frame), timestamp, ground-truth pose
  Image16 labels;  ///< plane id per pixel (0 = none), same size as the cloud
  std::vector<float> true_range;  ///< noise-free depth (pinhole) / range (spherical), NaN = none
  std::vector<float> intensity;   ///< reflectance per pixel (lidar), else empty
};

class SyntheticSequence : public Sequence {
 public:
  explicit SyntheticSequence(SyntheticConfig config);

  std::size_t Size() const override { return stamps_.size(); }
  Frame Load(std::size_t index) const override { return Generate(index).frame; }
  std::string Name() const override;
  double Timestamp(std::size_t index) const override;
  std::optional<Pose> GroundTruth(std::size_t index) const override;

  /// Frame i with its labels and noise-free ranges.
  SyntheticFrame Generate(std::size_t index) const;
  /// Label image of frame i (renders the frame).
  Image16 Labels(std::size_t index) const { return Generate(index).labels; }

  const SyntheticScene& scene() const { return scene_; }
  const SyntheticConfig& config() const { return config_; }
  const SyntheticSensor& sensor() const { return *sensor_; }
  /// Ground truth of all frames.
  Trajectory GroundTruthTrajectory() const;

 private:
  SyntheticConfig config_;
  SyntheticScene scene_;
  std::unique_ptr<SyntheticSensor> sensor_;
  std::vector<double> stamps_;
  std::vector<Pose> poses_;  // T_world_sensor
};

}  // namespace planeslam::datasets
