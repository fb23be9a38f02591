#include "planeslam/registration/velocity_model.hpp"

namespace planeslam::registration {

void VelocityModel::Add(double timestamp, double dt, const Pose& T_prev_curr) {
  if (!(dt > 0)) return;
  motions_.push_back({timestamp, dt, BoxMinus(T_prev_curr, Pose::Identity())});
  while (motions_.size() > 1 && motions_.front().timestamp < timestamp - window_) {
    motions_.pop_front();
  }
}

Pose VelocityModel::Predict(double dt) const {
  if (motions_.empty() || !(dt > 0)) return Pose::Identity();
  // Mean rate over the window (per-frame motions are small: their tangents add).
  Vector6d sum = Vector6d::Zero();
  double duration = 0.0;
  for (const Motion& m : motions_) {
    sum += m.delta;
    duration += m.dt;
  }
  return BoxPlus(Pose::Identity(), sum * (dt / duration));
}

}  // namespace planeslam::registration
