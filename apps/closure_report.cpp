#include "closure_report.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <map>
#include <sstream>

#include "planeslam/datasets/atomic_file.hpp"
#include "planeslam/datasets/closure_truth.hpp"
#include "planeslam/datasets/trajectory_io.hpp"

namespace planeslam::app {
namespace {

namespace ds = planeslam::datasets;

/// The record judged at its frames' stamps (the SLAM's trajectory has one pose per frame).
ds::ClosureTruth Judge(const mapping::LoopClosureRecord& record, const ds::Trajectory& estimate,
                       const ds::Trajectory& ground_truth) {
  if (ground_truth.size() < 2 || record.to_frame >= estimate.size()) return {};
  return ds::JudgeClosure(ground_truth, estimate.stamps[record.from_frame],
                          estimate.stamps[record.to_frame], record.T_from_to);
}

/// The reason without its figures ("inconsistent with the trajectory: chi2 31.2" -> the text
/// before the colon or parenthesis), for counting.
std::string ReasonKind(const std::string& reason) {
  const std::size_t cut = reason.find_first_of(":(");
  std::string kind = reason.substr(0, cut);
  while (!kind.empty() && kind.back() == ' ') kind.pop_back();
  return kind;
}

}  // namespace

void WriteClosuresCsv(const std::string& path, const mapping::SlamSystem& slam,
                      const ds::Trajectory& ground_truth) {
  const ds::Trajectory estimate = slam.EstimatedTrajectory();
  const bool judged = ground_truth.size() >= 2;
  std::ostringstream out;
  out << "from_frame,to_frame,from_keyframe,to_keyframe,x,y,z,qx,qy,qz,qw,chi2_trajectory,"
         "chi2_residual,support,status,reason,injected,decided_frame,shared_planes,shared_agreeing,"
         "map_vouched,verified_by"
      << (judged ? ",true,translation_error,rotation_error_deg" : "") << "\n";
  for (const mapping::LoopClosureRecord& r : slam.closures()) {
    const Eigen::Quaterniond q(r.T_from_to.rotation());
    const Eigen::Vector3d t = r.T_from_to.translation();
    out << r.from_frame << "," << r.to_frame << "," << r.from_keyframe << "," << r.to_keyframe;
    for (double v :
         {t.x(), t.y(), t.z(), q.x(), q.y(), q.z(), q.w(), r.chi2_trajectory, r.chi2_residual}) {
      out << "," << ds::FormatRoundTrip(v);
    }
    out << "," << r.support << "," << mapping::ClosureStatusName(r.status) << ",\"" << r.reason
        << "\"," << r.injected << "," << r.decided_frame << "," << r.shared_planes << ","
        << r.shared_agreeing << "," << r.map_vouched << "," << r.verified_by;
    if (judged) {
      const ds::ClosureTruth truth = Judge(r, estimate, ground_truth);
      out << "," << (truth.known ? (truth.correct ? "1" : "0") : "") << ","
          << ds::FormatRoundTrip(truth.translation_error) << ","
          << ds::FormatRoundTrip(truth.rotation_error_deg);
    }
    out << "\n";
  }
  ds::WriteFileAtomic(path, out.str());
}

nlohmann::json ClosuresJson(const mapping::SlamSystem& slam, const ds::Trajectory& ground_truth) {
  const ds::Trajectory estimate = slam.EstimatedTrajectory();
  std::map<std::string, std::size_t> by_status;
  std::map<std::string, std::map<std::string, std::size_t>> reasons;
  std::size_t false_accepted = 0, true_rejected = 0, judged = 0, injected_accepted = 0;
  for (const mapping::LoopClosureRecord& r : slam.closures()) {
    const std::string status = mapping::ClosureStatusName(r.status);
    ++by_status[status];
    ++reasons[status][ReasonKind(r.reason)];
    const bool accepted = r.status == mapping::ClosureStatus::kAccepted;
    if (r.injected && accepted) ++injected_accepted;
    const ds::ClosureTruth truth = Judge(r, estimate, ground_truth);
    if (!truth.known) continue;
    ++judged;
    if (accepted && !truth.correct) ++false_accepted;
    if (r.status == mapping::ClosureStatus::kRejected && truth.correct) ++true_rejected;
  }
  nlohmann::json json = {
      {"hypotheses", slam.closures().size()},   {"accepted", by_status["accepted"]},
      {"rejected", by_status["rejected"]},      {"retracted", by_status["retracted"]},
      {"pending", by_status["pending"]},        {"injected", slam.stats().closures_injected},
      {"injected_accepted", injected_accepted}, {"reasons", reasons}};
  if (judged > 0) {
    json["ground_truth"] = {
        {"judged", judged}, {"false_accepted", false_accepted}, {"true_rejected", true_rejected}};
  }
  return json;
}

nlohmann::json BackEndJson(const mapping::SlamSystem& slam) {
  const mapping::SlamStats& stats = slam.stats();
  const double timed =
      static_cast<double>(std::min<std::size_t>(stats.frames, mapping::SlamStats::kTimedFrames));
  return {{"optimizations", stats.optimizations},
          {"local_optimizations", stats.local_optimizations},
          {"optimizations_deferred", stats.optimizations_deferred},
          {"map_splits", stats.map_splits},
          {"map_planes_culled", stats.map_planes_culled},
          {"timed_frames", timed},
          {"slam_ms_per_frame_first", timed > 0 ? stats.time_first_frames_ms / timed : 0.0},
          {"slam_ms_per_frame_last", timed > 0 ? stats.time_last_frames_ms / timed : 0.0}};
}

}  // namespace planeslam::app
