#include "planeslam/detection/detection_config.hpp"

namespace planeslam::detection {

bool ParseThresholdModel(const std::string& text, ThresholdModel& model) {
  if (text == "constant") {
    model = ThresholdModel::kConstant;
    return true;
  }
  if (text == "depth") {
    model = ThresholdModel::kDepth;
    return true;
  }
  return false;
}

const char* ToString(ThresholdModel model) {
  return model == ThresholdModel::kConstant ? "constant" : "depth";
}

std::vector<std::string> DetectionParams::Validate() const {
  std::vector<std::string> problems;
  if (!(eta_deg > 0 && eta_deg < 90)) problems.push_back("eta_deg must be in (0, 90)");
  if (!(gamma > 0)) problems.push_back("gamma must be > 0");
  if (!(epsilon > 0)) problems.push_back("epsilon must be > 0");
  if (!(delta > 0)) problems.push_back("delta must be > 0");
  if (theta < 3) problems.push_back("theta must be >= 3 points");
  if (sigma0 < 0 || sigma_z2 < 0) problems.push_back("sigma0 and sigma_z2 must be >= 0");
  if (model == ThresholdModel::kDepth && sigma0 == 0 && sigma_z2 == 0)
    problems.push_back("threshold_model depth needs a noise model (sigma0 or sigma_z2 > 0)");
  if (!(merge_angle_deg >= 0 && merge_angle_deg < 90))
    problems.push_back("merge_angle_deg must be in [0, 90)");
  return problems;
}

}  // namespace planeslam::detection
