#pragma once
/// report.html: one self-contained page (three.js and the page's own code inlined, data as JSON)
/// that shows a `run` output folder (3-D plane map, keyframes, loop closures, ground truth, point
/// cloud, plots, summary) or a `detect` result. The page's templates live in web/report/ and are
/// embedded at build time (apps/CMakeLists.txt); a build made without web/node_modules carries no
/// page, and the writers then return false with ReportUnavailableReason().
#include <Eigen/Core>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "planeslam/datasets/organized_cloud.hpp"
#include "planeslam/datasets/trajectory.hpp"

namespace planeslam::app {

/// Whether this executable carries the page (three.js bundle and templates).
bool ReportAvailable();
/// One line saying why the report is not written (for a build without the page).
std::string ReportUnavailableReason();

/// The keyframe clouds (sensor frame, by keyframe id) at `poses`, voxel-thinned to at most
/// `max_points` points, written as an unorganized binary PCD (`keyframe_cloud.pcd` of a run).
/// Returns the number of points written.
std::size_t WriteKeyframeCloud(
    const std::string& path,
    const std::vector<std::pair<std::int64_t, std::vector<Eigen::Vector3f>>>& clouds,
    const std::unordered_map<std::int64_t, Pose>& poses, std::size_t max_points);

/// Writes DIR/report.html from the files of a `planeslam run` output folder: summary.json,
/// pose_graph.g2o and plane_map.json (required), metrics.json, config.yaml, frames.csv,
/// trajectory_tum.txt, ground_truth_tum.txt, keyframe_cloud.pcd and plots/*.svg (when present).
/// Throws IoError naming the file when a required one is missing or malformed; nothing is
/// written then. Returns false (nothing written) when the build carries no page.
bool WriteRunReport(const std::string& dir, std::size_t max_cloud_points);

/// What `planeslam detect` shows: its planes.json, the cloud (sensor frame) with one label per
/// pixel (plane id, <= 0 none) and a grey rendering of the range per pixel.
struct DetectReportInput {
  nlohmann::json planes;  ///< planes.json as written
  const datasets::OrganizedCloud* cloud = nullptr;
  const std::vector<int>* labels = nullptr;
  const std::vector<std::uint8_t>* grey = nullptr;
  std::string config_yaml;
};

/// Writes `path` (report.html of `detect`): depth and labelled images side by side, the plane
/// table and the segmented points in 3-D (at most `max_points`). Returns false when the build
/// carries no page.
bool WriteDetectReport(const std::string& path, const DetectReportInput& input,
                       std::size_t max_points);

/// The page with `data` embedded (exposed for tests): template, style, script and data joined.
std::string AssembleReportHtml(const std::string& title, const nlohmann::json& data);

}  // namespace planeslam::app
