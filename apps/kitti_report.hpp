#pragma once
/// The KITTI odometry segment errors as `eval kitti`, `bench odometry` and `run` report them.
#include <nlohmann/json.hpp>

#include <optional>
#include <string>

#include "planeslam/datasets/kitti_odometry_eval.hpp"
#include "planeslam/datasets/trajectory.hpp"

namespace planeslam::app {

/// Summary lines (translation %, rotation deg/100 m, segments) and the per-length table.
std::string FormatKittiErrors(const datasets::KittiOdometryResult& result, std::size_t pairs);

/// {"translation_percent", "rotation_deg_per_100m", "segments", "path_length_m",
///  "per_length": [{"length_m", "segments", "translation_percent", "rotation_deg_per_100m"}]}.
nlohmann::json KittiErrorsJson(const datasets::KittiOdometryResult& result);

/// True when the folder is a KITTI-layout sequence (velodyne/ or .bin scans) with poses.txt or
/// KITTI's dataset/poses/NN.txt: its ground truth is KITTI-style.
bool HasKittiGroundTruth(const std::string& sequence_path);

/// The segment errors of `estimate` against `ground_truth` (paired by equal stamps), or nullopt
/// when fewer than two poses pair up. result.ok is false when the path is too short.
std::optional<datasets::KittiOdometryResult> KittiErrors(const datasets::Trajectory& ground_truth,
                                                         const datasets::Trajectory& estimate);

/// For `run`: when the sequence's ground truth is KITTI-style, adds "kitti" to `metrics` (the
/// errors, or {"error": why not}) and the two summary lines to `report`.
void AddKittiErrors(const std::string& sequence_path, const datasets::Trajectory& ground_truth,
                    const datasets::Trajectory& estimate, nlohmann::json* metrics,
                    std::string* report);

}  // namespace planeslam::app
