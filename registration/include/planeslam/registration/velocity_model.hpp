#pragma once
/// Constant-velocity prediction from recent frame-to-frame motions: the velocity is their mean
/// rate over a time window, so that one frame's error does not become the velocity of the frames
/// that follow (it is held through stretches whose motion the planes cannot determine).
#include <deque>

#include "planeslam/registration/geometry.hpp"

namespace planeslam::registration {

class VelocityModel {
 public:
  /// `window` [s]: motions that ended more than this before the latest one are forgotten; 0 keeps
  /// only the latest.
  explicit VelocityModel(double window = 0.0) : window_(window) {}

  /// Adds the motion T_prev_curr of a frame at `timestamp` that came `dt` seconds after the
  /// previous one; ignored unless dt > 0.
  void Add(double timestamp, double dt, const Pose& T_prev_curr);
  /// Predicted T_prev_curr for a frame `dt` seconds after the previous one (identity without
  /// motions or for dt <= 0).
  Pose Predict(double dt) const;
  bool empty() const { return motions_.empty(); }
  void Clear() { motions_.clear(); }

 private:
  struct Motion {
    double timestamp;
    double dt;
    Vector6d delta;  ///< BoxMinus(T_prev_curr, identity)
  };
  double window_;
  std::deque<Motion> motions_;
};

}  // namespace planeslam::registration
