#include "planeslam/registration/velocity_model.hpp"

#include <algorithm>
#include <vector>

#include "planeslam/registration/theil_sen.hpp"

namespace planeslam::registration {

void VelocityModel::AddTo(std::deque<Motion>& motions, double* held_time, double timestamp,
                          double dt, const Eigen::Vector3d& delta, int span) {
  Eigen::Vector3d motion = delta;
  if (span > 1 && !motions.empty()) {
    const Eigen::Vector3d held = Rate(motions, dt);
    motion = held + (delta - held) / span;
  }
  if (!motions.empty()) {
    // Frames between the last motion and this one were held.
    const double gap = (timestamp - dt) - motions.back().timestamp;
    if (gap > 0.5 * dt) *held_time += gap;
  }
  const double measured_time = timestamp - *held_time;
  motions.push_back({timestamp, dt, motion, measured_time});
  while (motions.size() > 1 && motions.front().measured_time < measured_time - window_) {
    motions.pop_front();
  }
}

void VelocityModel::Add(double timestamp, double dt, const Pose& T_prev_curr,
                        bool translation_known, bool rotation_known, int translation_span,
                        int rotation_span) {
  if (!(dt > 0)) return;
  const Vector6d delta = BoxMinus(T_prev_curr, Pose::Identity());
  if (translation_known) {
    AddTo(translation_, &translation_held_, timestamp, dt, delta.head<3>(), translation_span);
  }
  if (rotation_known) {
    AddTo(rotation_, &rotation_held_, timestamp, dt, delta.tail<3>(), rotation_span);
  }
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

Eigen::Vector3d VelocityModel::TrendRate(const std::deque<Motion>& motions, double at, double dt) {
  if (motions.size() < 4) return Rate(motions, dt);
  // Each motion's rate belongs to the middle of its interval; times relative to the latest end.
  const double t_latest = motions.back().timestamp;
  std::vector<double> t;
  std::vector<Eigen::Vector3d> rate;
  for (const Motion& m : motions) {
    t.push_back(m.timestamp - 0.5 * m.dt - t_latest);
    rate.push_back(m.delta / m.dt);
  }
  // A Theil-Sen line: one wrong motion at the end of the window, where a least-squares line has
  // the most leverage, does not set the trend that the held turn is continued along.
  const TheilSenLine line = FitTheilSenLine(t, rate, 0.0);
  if (!line.valid) return Rate(motions, dt);
  return (line.value + line.slope * at) * dt;
}

Pose VelocityModel::PredictContinuingHeldTurn(double dt, double timestamp) const {
  if (rotation_.empty() || !(dt > 0)) return Predict(dt);
  const double since = timestamp - rotation_.back().timestamp;  // end of the last known turn
  if (!(since > 1.5 * dt)) return Predict(dt);                  // not held: the mean
  Vector6d delta;
  delta << Rate(translation_, dt), TrendRate(rotation_, std::min(since - 0.5 * dt, window_), dt);
  return BoxPlus(Pose::Identity(), delta);
}

Pose VelocityModel::Predict(double dt) const {
  if (empty() || !(dt > 0)) return Pose::Identity();
  Vector6d delta;
  delta << Rate(translation_, dt), Rate(rotation_, dt);
  return BoxPlus(Pose::Identity(), delta);
}

}  // namespace planeslam::registration
