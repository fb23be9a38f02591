#pragma once
// The loop-closure hypotheses of a run: closures.csv and the "closures" block of summary.json,
// each judged against the ground truth when there is one.
#include <nlohmann/json.hpp>
#include <string>

#include "planeslam/datasets/trajectory.hpp"
#include "planeslam/mapping/slam_system.hpp"

namespace planeslam::app {

/// closures.csv: one row per hypothesis (frame pair, keyframe pair, relative pose x y z qx qy qz
/// qw, chi2 against the trajectory and after optimisation, support, status, reason, injected,
/// decided_frame, the map planes both keyframes see and those the pose agrees with, and with
/// ground truth: true, translation and rotation error).
void WriteClosuresCsv(const std::string& path, const mapping::SlamSystem& slam,
                      const datasets::Trajectory& ground_truth);

/// Counts per status and reason; with ground truth the false closures accepted and the true
/// ones rejected.
nlohmann::json ClosuresJson(const mapping::SlamSystem& slam,
                            const datasets::Trajectory& ground_truth);

/// The back end's cost: optimisations (whole and windowed) and the SLAM time per frame over the
/// first and the last SlamStats::kTimedFrames frames [ms].
nlohmann::json BackEndJson(const mapping::SlamSystem& slam);

}  // namespace planeslam::app
