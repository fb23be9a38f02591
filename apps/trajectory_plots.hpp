#pragma once
/// SVG plots of trajectory evaluations, shared by `planeslam eval` and `planeslam run`.
#include <string>
#include <vector>

#include "planeslam/datasets/trajectory.hpp"
#include "planeslam/datasets/trajectory_eval.hpp"
#include "svg_plot.hpp"

namespace planeslam::app {

/// Top view (x, y): the reference dashed, the estimate as a line, and `coloured` poses as points
/// coloured by `errors` (one per coloured pose) labelled `label`.
void PlotTrajectories(const std::string& path, const std::string& title,
                      const std::vector<Pose>& ref, const std::vector<Pose>& est,
                      const std::vector<Pose>& coloured, const std::vector<double>& errors,
                      const std::string& label);

/// Error against time since the first stamp, with rmse/mean/median lines.
void PlotErrorOverTime(const std::string& path, const std::string& title,
                       const std::vector<double>& stamps, const std::vector<double>& errors,
                       const datasets::ErrorStatistics& stats, const std::string& label);

/// Horizontal rmse, mean and median lines.
void AddStatLines(SvgPlot& plot, const datasets::ErrorStatistics& stats);

/// "%.6f", the precision evo and the TUM tools print.
std::string Fixed6(double value);

}  // namespace planeslam::app
