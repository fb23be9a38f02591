#pragma once
/// The street scene: an urban block for LiDAR sequences, and the route a car drives around it.
///
/// World frame: z up, metres, the road crown at z = 0. Four straight streets (10 m wide, 2 %
/// camber from the crown down to the kerbs) enclose the central block; they cross at four
/// intersections and continue as side streets that end at a building. Kerbs (0.15 m) separate
/// the roads from 3 m sidewalks; buildings line every block side that faces a street, with
/// setbacks (recesses), recessed doors and shop windows. Street furniture: lamp poles, sign posts
/// with a plate, trees (trunk cylinder and spherical crown: non-planar clutter) and parked cars
/// (two boxes each). The road layout is fixed; the buildings, cars and furniture are drawn from
/// the seed.
///
/// The route drives counter-clockwise around the central block in the right lane, turning left
/// at each intersection on a 12 m arc, at `speed` on the straights and half of it in the turns
/// (2 m/s^2 braking and acceleration), `laps` times around the block so that it passes its start
/// again. The car's attitude follows the road surface under its four wheels; a small suspension
/// motion is added. The scanner sits 1.73 m above the road (KITTI's Velodyne), x forward, y left,
/// z up.
#include <Eigen/Core>

#include <cstdint>
#include <vector>

#include "planeslam/datasets/synthetic_scene.hpp"
#include "planeslam/datasets/trajectory.hpp"

namespace planeslam::datasets {

struct SyntheticTrajectoryConfig;

/// Fixed dimensions of the street layout [m].
struct StreetLayout {
  double street_x = 90.0;       ///< north-south streets' centre lines at x = +-street_x
  double street_y = 55.0;       ///< east-west streets' centre lines at y = +-street_y
  double road_half_width = 5.0;  ///< crown to kerb
  double camber = 0.02;          ///< road slope from the crown to the kerb [1]
  double kerb = 0.15;            ///< kerb height above the road edge
  double sidewalk = 3.0;         ///< kerb to building line
  double side_street = 35.0;     ///< side streets: crossing centre to the closing building
  double lane_offset = 1.7;      ///< route: right of the centre line
  double turn_radius = 12.0;     ///< route: left turns at the crossings
  double scanner_height = 1.73;  ///< scanner above the road
};

/// The layout every street scene and route uses.
const StreetLayout& DefaultStreetLayout();

/// The street scene for `seed` (buildings, cars and furniture drawn from it).
SyntheticScene MakeStreetScene(std::uint64_t seed);

/// Height of the ground (road or sidewalk top) at (x, y) [m].
double StreetGroundHeight(double x, double y);

/// Route length for `laps` turns around the central block [m].
double StreetRouteLength(double laps);

/// The route for a trajectory config (speed = speed on the straights, laps), sampled in time.
class StreetRoute {
 public:
  explicit StreetRoute(const SyntheticTrajectoryConfig& config);
  /// Time to drive the whole route [s].
  double Duration() const { return duration_; }
  double Length() const { return length_; }
  /// Arc length driven at time t (clamped to the route) [m].
  double ArcLength(double t) const;
  /// Scanner pose T_world_scanner at time t [s].
  Pose ScannerPose(double t) const;

 private:
  struct Phase {  // constant acceleration from v0 at s0 to v1 at s1, entered at time t0
    double s0, s1, v0, v1, t0;
  };
  std::vector<Phase> phases_;
  double length_ = 0.0;
  double duration_ = 0.0;
  double pitch_amplitude_ = 0.0;   // [rad]
  double roll_amplitude_ = 0.0;    // [rad]
  double height_amplitude_ = 0.0;  // [m]
};

}  // namespace planeslam::datasets
