// Map-plane culling (SlamSystem): a plane the keyframes looked at again and again without
// detecting it is not a stable surface (a facet of a curved object, one view's split of a wall,
// a thing that moved), whatever its few detections said.
#include <algorithm>
#include <cmath>
#include <unordered_set>

#include "planeslam/mapping/slam_system.hpp"

namespace planeslam::mapping {

namespace {

/// Of each map plane's world samples, at most this many evenly spaced ones are checked.
constexpr std::size_t kCullSamples = 32;
/// A keyframe saw a plane when at least half of its samples facing it were reached by its lines
/// of sight: on or in front of the nearest return within max(kSightTolerance, range *
/// kSightRangeTolerance).
constexpr double kSightTolerance = 0.05;       // [m]
constexpr double kSightRangeTolerance = 0.02;  // [-]
/// Views within 75 deg of the plane's normal; at grazing angles the detectors find nothing.
constexpr double kMinViewCosine = 0.26;
/// Keyframes count as looking at a plane only within this factor of the longest range it was
/// detected from: farther, it covers too few pixels for the detector's minimum size.
constexpr double kRangeFactor = 1.25;
/// Detected in fewer than this share of the keyframes that looked at it, after at least
/// kMinLooks looks: ORB-SLAM's criterion for map points (found / visible < 0.25).
constexpr double kMinDetectedShare = 0.25;
constexpr int kMinLooks = 5;
/// A keyframe this close to one that detected a plane saw nearly the same image of it, and so
/// looked at it whatever the plane's normal says: a plane fitted across clutter has an arbitrary
/// normal, which the facing test would take at its word. Applied to planes detected fewer than
/// kMinLooks times, which the sight test alone could never judge.
constexpr double kSameViewTranslation = 0.10;  // [m]
constexpr double kSameViewAngleDeg = 5.0;

/// Whether two keyframes (their T_sensor_world) stood at nearly the same viewpoint.
bool SameView(const Pose& a_sensor_world, const Pose& b_sensor_world) {
  static const double min_trace = 1.0 + 2.0 * std::cos(kSameViewAngleDeg * M_PI / 180.0);
  const Pose d = a_sensor_world * b_sensor_world.inverse();  // T_a_b
  // The rotation angle theta of d: trace = 1 + 2 cos(theta).
  return d.translation().norm() <= kSameViewTranslation && d.linear().trace() >= min_trace;
}

}  // namespace

int SlamSystem::CullUnconfirmedPlanes() {
  std::vector<Pose> T_sensor_world(keyframes_.size());
  for (const Keyframe& keyframe : keyframes_) {
    T_sensor_world[static_cast<std::size_t>(keyframe.id)] = KeyframePose(keyframe.id).inverse();
  }
  std::unordered_set<int> culled;
  const double cos_gate = std::cos(config_.landmark_gate_deg * M_PI / 180.0);
  for (const MapPlane& plane : map_.planes()) {
    // Keyframes that detected the plane where it is: within the gates of the landmark
    // residuals, at the final poses. A facet of a curved surface collects detections of
    // neighbouring facets (the map's association is looser), which confirm nothing.
    std::unordered_set<std::int64_t> detected, confirmed;
    double longest = 0.0;
    for (const PlaneObservation& obs : plane.observations) {
      detected.insert(obs.keyframe_id);
      longest = std::max(longest, obs.stats_sensor.centroid.norm());
      const Pose T_world_keyframe = KeyframePose(obs.keyframe_id);
      const Eigen::Vector3d n = T_world_keyframe.linear() * obs.normal_sensor;
      const Eigen::Vector3d c = T_world_keyframe * obs.stats_sensor.centroid;
      if (n.dot(plane.normal) >= cos_gate &&
          std::abs(plane.normal.dot(c) - plane.d) <= config_.landmark_gate_offset) {
        confirmed.insert(obs.keyframe_id);
      }
    }
    std::vector<Eigen::Vector3d> all = map_.WorldSamples(plane);
    // An observation keeps only the samples that extended its plane; one split off later (a merge
    // the final poses contradict) may have none. Its centroid is then where it was seen.
    if (all.empty()) {
      for (const PlaneObservation& obs : plane.observations) {
        all.push_back(KeyframePose(obs.keyframe_id) * obs.stats_sensor.centroid);
      }
    }
    std::vector<Eigen::Vector3d> samples;
    const std::size_t step = std::max<std::size_t>(1, all.size() / kCullSamples);
    for (std::size_t i = 0; i < all.size(); i += step) samples.push_back(all[i]);
    if (samples.empty()) continue;
    int looks = static_cast<int>(detected.size());
    for (const Keyframe& keyframe : keyframes_) {
      if (detected.count(keyframe.id) > 0) continue;
      const Pose& T = T_sensor_world[static_cast<std::size_t>(keyframe.id)];
      if (detected.size() < static_cast<std::size_t>(kMinLooks) &&
          std::any_of(detected.begin(), detected.end(), [&](std::int64_t id) {
            return SameView(T, T_sensor_world[static_cast<std::size_t>(id)]);
          })) {
        ++looks;
        continue;
      }
      if (keyframe.view.empty()) continue;
      if ((T * plane.centroid).norm() > kRangeFactor * longest) continue;
      const Eigen::Vector3d n_sensor = T.linear() * plane.normal;
      int facing = 0, reached = 0;
      for (const Eigen::Vector3d& sample : samples) {
        const Eigen::Vector3d p = T * sample;
        const double range = p.norm();
        // The normal points away from the sensors that see the plane's front.
        if (!(n_sensor.dot(p) >= kMinViewCosine * range)) continue;
        ++facing;
        const double tolerance = std::max(kSightTolerance, kSightRangeTolerance * range);
        if (keyframe.view.Reaches(p, tolerance)) ++reached;
      }
      if (facing > 0 && 2 * reached >= static_cast<int>(samples.size())) ++looks;
    }
    if (looks >= kMinLooks &&
        static_cast<double>(confirmed.size()) < kMinDetectedShare * static_cast<double>(looks)) {
      culled.insert(plane.id);
    }
  }
  const int removed = map_.Remove(culled);
  stats_.map_planes_culled += static_cast<std::size_t>(removed);
  return removed;
}

}  // namespace planeslam::mapping
