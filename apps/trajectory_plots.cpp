#include "trajectory_plots.hpp"

#include <cstdio>

namespace planeslam::app {
namespace {

/// At most `max_points` evenly spread samples of a polyline (20k-pose ground truths in a plot).
std::vector<std::size_t> Decimate(std::size_t n, std::size_t max_points) {
  std::vector<std::size_t> ids;
  const std::size_t step = n > max_points ? (n + max_points - 1) / max_points : 1;
  for (std::size_t i = 0; i < n; i += step) ids.push_back(i);
  if (n > 0 && ids.back() != n - 1) ids.push_back(n - 1);
  return ids;
}

void XY(const std::vector<Pose>& poses, std::vector<double>& x, std::vector<double>& y,
        std::size_t max_points = 5000) {
  for (std::size_t i : Decimate(poses.size(), max_points)) {
    x.push_back(poses[i].translation().x());
    y.push_back(poses[i].translation().y());
  }
}

}  // namespace

std::string Fixed6(double value) {
  char buffer[64];
  std::snprintf(buffer, sizeof(buffer), "%.6f", value);
  return buffer;
}

void AddStatLines(SvgPlot& plot, const datasets::ErrorStatistics& s) {
  LineStyle rmse{CycleColor(3), 1.5, false}, mean{CycleColor(2), 1.5, true},
      median{CycleColor(1), 1.5, true};
  plot.AddHorizontalLine(s.rmse, rmse, "rmse " + Fixed6(s.rmse));
  plot.AddHorizontalLine(s.mean, mean, "mean " + Fixed6(s.mean));
  plot.AddHorizontalLine(s.median, median, "median " + Fixed6(s.median));
}

void PlotTrajectories(const std::string& path, const std::string& title,
                      const std::vector<Pose>& ref, const std::vector<Pose>& est,
                      const std::vector<Pose>& coloured, const std::vector<double>& errors,
                      const std::string& label) {
  SvgPlot plot(title, "x [m]", "y [m]");
  plot.SetSize(900, 700);
  plot.SetEqualAspect(true);
  std::vector<double> rx, ry, ex, ey, cx, cy;
  XY(ref, rx, ry);
  XY(est, ex, ey);
  XY(coloured, cx, cy, coloured.size());
  plot.AddLine(rx, ry, LineStyle{SvgColor{80, 80, 80}, 1.5, true}, "reference");
  plot.AddLine(ex, ey, LineStyle{SvgColor{190, 190, 190}, 1.0, false}, "estimate");
  plot.AddColorMappedScatter(cx, cy, errors, label);
  plot.Write(path);
}

void PlotErrorOverTime(const std::string& path, const std::string& title,
                       const std::vector<double>& stamps, const std::vector<double>& errors,
                       const datasets::ErrorStatistics& stats, const std::string& label) {
  SvgPlot plot(title, "t - t0 [s]", label);
  std::vector<double> t(stamps.size());
  for (std::size_t i = 0; i < stamps.size(); ++i) t[i] = stamps[i] - stamps.front();
  plot.AddLine(t, errors, LineStyle{CycleColor(7), 1.2, false}, "error");
  AddStatLines(plot, stats);
  plot.Write(path);
}

}  // namespace planeslam::app
