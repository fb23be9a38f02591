#include "planeslam/registration/velocity_model.hpp"

namespace planeslam::registration {

void VelocityModel::AddTo(std::deque<Motion>& motions, double timestamp, double dt,
                          const Eigen::Vector3d& delta) const {
  motions.push_back({timestamp, dt, delta});
  while (motions.size() > 1 && motions.front().timestamp < timestamp - window_) {
    motions.pop_front();
  }
}

void VelocityModel::Add(double timestamp, double dt, const Pose& T_prev_curr,
                        bool translation_known, bool rotation_known) {
  if (!(dt > 0)) return;
  const Vector6d delta = BoxMinus(T_prev_curr, Pose::Identity());
  if (translation_known) AddTo(translation_, timestamp, dt, delta.head<3>());
  if (rotation_known) AddTo(rotation_, timestamp, dt, delta.tail<3>());
}

Eigen::Vector3d VelocityModel::Rate(const std::deque<Motion>& motions, double dt) {
  if (motions.empty()) return Eigen::Vector3d::Zero();
  // Mean rate over the window (per-frame motions are small: their tangents add).
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  double duration = 0.0;
  for (const Motion& m : motions) {
    sum += m.delta;
    duration += m.dt;
  }
  return sum * (dt / duration);
}

Pose VelocityModel::Predict(double dt) const {
  if (empty() || !(dt > 0)) return Pose::Identity();
  Vector6d delta;
  delta << Rate(translation_, dt), Rate(rotation_, dt);
  return BoxPlus(Pose::Identity(), delta);
}

}  // namespace planeslam::registration
