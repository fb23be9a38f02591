#pragma once
/// Constant-velocity prediction from recent frame-to-frame motions: the velocity is their mean
/// rate over a time window, so that one frame's error does not become the velocity of the frames
/// that follow (it is held through stretches whose motion the planes cannot determine). The
/// window runs over measured time, so a held stretch does not empty it.
#include <deque>

#include "planeslam/registration/geometry.hpp"

namespace planeslam::registration {

class VelocityModel {
 public:
  /// `window` [s]: motions that ended more than this before the latest one, not counting the
  /// time a part was held, are forgotten; 0 keeps only the latest.
  explicit VelocityModel(double window = 0.0) : window_(window) {}

  /// Adds the motion T_prev_curr of a frame at `timestamp` that came `dt` seconds after the
  /// previous one; ignored unless dt > 0. A part the caller does not trust (e.g. translation the
  /// planes left to the prior) is left out: that part keeps the rate of its own last motions.
  ///
  /// A part measured now but left to the prior at the previous frame(s) moved by its rate plus
  /// the correction of what the prior drifted since it was last measured: `*_span` > 1 frames
  /// spread that correction over those frames (the held rate plus 1/span of the difference)
  /// instead of taking it for one frame's rate.
  void Add(double timestamp, double dt, const Pose& T_prev_curr, bool translation_known = true,
           bool rotation_known = true, int translation_span = 1, int rotation_span = 1);
  /// Predicted T_prev_curr for a frame `dt` seconds after the previous one (identity without
  /// motions or for dt <= 0).
  Pose Predict(double dt) const;
  /// The same for the frame at `timestamp`, with the rotation rate continued along the trend of
  /// its window (Theil-Sen line, constant angular acceleration) while it is being held, i.e.
  /// its latest motion ended before the previous frame; at most `window` beyond that motion.
  Pose PredictContinuingHeldTurn(double dt, double timestamp) const;
  bool empty() const { return translation_.empty() && rotation_.empty(); }
  void Clear() {
    translation_.clear();
    rotation_.clear();
    translation_held_ = rotation_held_ = 0.0;
  }

 private:
  struct Motion {
    double timestamp;
    double dt;
    Eigen::Vector3d delta;  ///< translation, or rotation vector, of the frame's motion
    double measured_time;   ///< timestamp less the part's held time before it [s]
  };
  /// Adds to one part's window and forgets what the window has passed. The window runs over
  /// measured time: time the part was held does not count, so after a held stretch the first
  /// measured motions are averaged with those before it instead of standing alone.
  void AddTo(std::deque<Motion>& motions, double* held_time, double timestamp, double dt,
             const Eigen::Vector3d& delta, int span);
  /// Mean rate of one part's window times dt (zero without motions).
  static Eigen::Vector3d Rate(const std::deque<Motion>& motions, double dt);
  /// The rate of the Theil-Sen line through the window's rates at time `at` (relative to the
  /// latest motion's end), times dt; the mean rate with fewer than 4 motions.
  static Eigen::Vector3d TrendRate(const std::deque<Motion>& motions, double at, double dt);
  double window_;
  std::deque<Motion> translation_;
  std::deque<Motion> rotation_;
  double translation_held_ = 0.0, rotation_held_ = 0.0;  ///< time each part was held [s]
};

}  // namespace planeslam::registration
