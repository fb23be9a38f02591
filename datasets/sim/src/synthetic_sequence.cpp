// Synthetic trajectories and the in-memory SyntheticSequence.
#include <cmath>

#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/synthetic_sequence.hpp"
#include "planeslam/datasets/synthetic_street.hpp"
#include "synthetic_random.hpp"

namespace planeslam::datasets {

namespace {
constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180.0;

// Oscillations per lap (loop) chosen not to be whole numbers, so the second pass near the start
// sees the scene from a slightly different height/pitch/yaw: loop closure must match, not copy.
constexpr double kYawCyclesPerLap = 2.1;
constexpr double kPitchCyclesPerLap = 2.2;
constexpr double kHeightCyclesPerLap = 1.3;
constexpr double kRollCyclesPerLap = 4.3;
// Line: wavelengths along the run [m].
constexpr double kYawWave = 6.0, kPitchWave = 7.0, kHeightWave = 5.0, kLateralWave = 4.0,
                 kRollWave = 3.0;

Eigen::Matrix3d BodyRotation(double yaw, double pitch, double roll) {
  // Yaw about z, then pitch (positive = nose up, i.e. -pitch about the body's left axis), then roll
  // about the forward axis.
  return (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) *
          Eigen::AngleAxisd(-pitch, Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}
}  // namespace

SyntheticTrajectoryConfig DefaultTrajectory(SceneKind kind) {
  SyntheticTrajectoryConfig c;
  switch (kind) {
    case SceneKind::kRoom:
      break;  // the struct defaults are the room's
    case SceneKind::kCorridor:
      c.kind = "line";
      c.center = Eigen::Vector3d(2.0, 0.0, 1.4);
      c.length = 10.0;
      c.speed = 0.5;
      c.height_amplitude = 0.1;
      c.pitch_deg = -5.0;
      c.pitch_amplitude_deg = 5.0;
      c.yaw_amplitude_deg = 15.0;
      break;
    case SceneKind::kRubble:
      c.center = Eigen::Vector3d(0.0, 0.0, 1.6);
      c.radius = 3.8;
      c.start_angle_deg = -90.0;
      c.look = "inward";
      c.speed = 1.0;
      c.laps = 1.25;
      c.height_amplitude = 0.2;
      c.pitch_deg = -25.0;
      c.yaw_amplitude_deg = 20.0;
      break;
    case SceneKind::kStreet:
      c.kind = "street";
      c.rate = 10.0;
      c.speed = 10.0;
      c.laps = 1.15;
      c.pitch_amplitude_deg = 0.1;
      c.roll_amplitude_deg = 0.08;
      c.height_amplitude = 0.005;
      break;
  }
  return c;
}

int TrajectoryFrameCount(const SyntheticTrajectoryConfig& c) {
  if (c.frames > 0) return c.frames;
  PLANESLAM_CHECK(c.speed > 0 && c.rate > 0, "speed and rate must be positive");
  if (c.kind == "street") {
    return std::max(1, static_cast<int>(std::floor(StreetRoute(c).Duration() * c.rate)) + 1);
  }
  const double path = c.kind == "line" ? c.length : c.laps * 2.0 * kPi * c.radius;
  return std::max(1, static_cast<int>(std::lround(path / c.speed * c.rate)));
}

Pose TrajectoryBodyPose(const SyntheticTrajectoryConfig& c, double t) {
  if (c.kind == "street") return StreetRoute(c).ScannerPose(t);
  const double s = c.speed * t;  // arc length [m]
  Pose T = Pose::Identity();
  if (c.kind == "line") {
    const double yaw = c.yaw_amplitude_deg * kDeg * std::sin(2 * kPi * s / kYawWave);
    const double pitch =
        (c.pitch_deg + c.pitch_amplitude_deg * std::sin(2 * kPi * s / kPitchWave)) * kDeg;
    const double roll = c.roll_amplitude_deg * kDeg * std::sin(2 * kPi * s / kRollWave);
    T.translation() = c.center + Eigen::Vector3d(s, c.lateral_amplitude * std::sin(2 * kPi * s / kLateralWave),
                                                 c.height_amplitude * std::sin(2 * kPi * s / kHeightWave));
    T.linear() = BodyRotation(yaw, pitch, roll);
    return T;
  }
  PLANESLAM_CHECK(c.kind == "loop", "unknown trajectory kind '" << c.kind << "'");
  PLANESLAM_CHECK(c.radius > 0, "loop radius must be positive");
  const double lap = 2.0 * kPi * c.radius;
  const double phase = 2 * kPi * s / lap;  // angle travelled
  const double theta = c.start_angle_deg * kDeg + phase;
  double heading = theta;                  // outward
  if (c.look == "inward") {
    heading = theta + kPi;
  } else if (c.look == "forward") {
    heading = theta + 0.5 * kPi;
  } else {
    PLANESLAM_CHECK(c.look == "outward", "unknown look '" << c.look << "'");
  }
  const double yaw = heading + c.yaw_amplitude_deg * kDeg * std::sin(kYawCyclesPerLap * phase);
  const double pitch =
      (c.pitch_deg + c.pitch_amplitude_deg * std::sin(kPitchCyclesPerLap * phase)) * kDeg;
  const double roll = c.roll_amplitude_deg * kDeg * std::sin(kRollCyclesPerLap * phase);
  T.translation() =
      c.center + Eigen::Vector3d(c.radius * std::cos(theta), c.radius * std::sin(theta),
                                 c.height_amplitude * std::sin(kHeightCyclesPerLap * phase));
  T.linear() = BodyRotation(yaw, pitch, roll);
  return T;
}

SyntheticConfig SyntheticConfig::ForScene(SceneKind scene) {
  SyntheticConfig c;
  c.scene = scene;
  c.trajectory = DefaultTrajectory(scene);
  if (scene == SceneKind::kStreet) c.sensor = "lidar";
  return c;
}

SyntheticSequence::SyntheticSequence(SyntheticConfig config)
    : config_(std::move(config)), scene_(MakeScene(config_.scene, config_.seed)) {
  if (config_.sensor == "pinhole") {
    sensor_ = MakePinholeSensor(scene_, config_.pinhole);
  } else if (config_.sensor == "spherical") {
    sensor_ = MakeSphericalSensor(scene_, config_.spherical);
  } else if (config_.sensor == "lidar") {
    PLANESLAM_CHECK(config_.trajectory.rate > 0, "frame rate must be positive");
    sensor_ = std::make_unique<RotatingLidar>(scene_, config_.lidar, 1.0 / config_.trajectory.rate);
  } else {
    throw ConfigError("unknown synthetic sensor '" + config_.sensor +
                      "' (expected pinhole, spherical or lidar)");
  }
  const int n = TrajectoryFrameCount(config_.trajectory);
  Pose body_sensor = Pose::Identity();
  if (config_.sensor == "pinhole") body_sensor.linear() = BodyFromOptical();
  for (int i = 0; i < n; ++i) {
    // Stamps are rounded to microseconds, the precision written to depth.txt, and the pose is
    // evaluated at the rounded stamp so files and memory agree exactly.
    const double t = std::round(i / config_.trajectory.rate * 1e6) / 1e6;
    stamps_.push_back(t);
    poses_.push_back(TrajectoryBodyPose(config_.trajectory, t) * body_sensor);
  }
}

std::string SyntheticSequence::Name() const {
  return "synthetic_" + SceneName(config_.scene);
}

double SyntheticSequence::Timestamp(std::size_t index) const {
  PLANESLAM_CHECK(index < stamps_.size(), "frame " << index << " out of range");
  return stamps_[index];
}

std::optional<Pose> SyntheticSequence::GroundTruth(std::size_t index) const {
  PLANESLAM_CHECK(index < poses_.size(), "frame " << index << " out of range");
  return poses_[index];
}

SyntheticFrame SyntheticSequence::Generate(std::size_t index) const {
  PLANESLAM_CHECK(index < poses_.size(), "frame " << index << " out of range");
  const std::uint64_t noise_seed = MixSeed(MixSeed(config_.seed) + index);
  const auto* lidar = dynamic_cast<const RotatingLidar*>(sensor_.get());
  SyntheticRender render =
      lidar != nullptr && config_.lidar.motion_distortion
          ? lidar->RenderMoving(
                [this, index](double dt) {
                  return TrajectoryBodyPose(config_.trajectory, stamps_[index] + dt);
                },
                noise_seed)
          : sensor_->Render(poses_[index], noise_seed);
  SyntheticFrame out;
  out.frame.index = index;
  out.frame.timestamp = stamps_[index];
  out.frame.source = Name() + "#" + std::to_string(index);
  out.frame.cloud = std::move(render.cloud);
  out.frame.T_world_sensor_gt = poses_[index];
  out.labels = std::move(render.labels);
  out.true_range = std::move(render.true_range);
  out.intensity = std::move(render.intensity);
  return out;
}

Trajectory SyntheticSequence::GroundTruthTrajectory() const {
  Trajectory t;
  for (std::size_t i = 0; i < poses_.size(); ++i) t.Add(stamps_[i], poses_[i]);
  return t;
}

}  // namespace planeslam::datasets
