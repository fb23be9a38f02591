#pragma once
/// `planeslam batch collect DIR`: every job's metrics.json and summary.json in one table, like
/// evo_res: ATE, RPE, frames/s, keyframes and loop closures per job, each variant's mean and worst
/// over the sequences, failed and missing jobs marked with their error; plus SVG plots comparing
/// the variants per sequence.
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "batch_manifest.hpp"

namespace planeslam::app {

/// The plan a batch writes to DIR/.batch/jobs.json (what collect reads back).
nlohmann::json PlanJson(const BatchPlan& plan, const std::string& binary,
                        const std::string& batch_dir);
/// Reads DIR/.batch/jobs.json back; throws IoError naming it when absent or malformed.
BatchPlan ReadPlanJson(const std::string& batch_dir);

struct CollectOutput {
  std::string markdown;       ///< what results.md holds
  std::vector<std::string> files;  ///< everything written
  int complete = 0, failed = 0, missing = 0;
};

/// Writes DIR/results.{md,csv,json}, DIR/results_variants.csv and DIR/compare_*.svg.
CollectOutput CollectBatch(const std::string& batch_dir);

}  // namespace planeslam::app
