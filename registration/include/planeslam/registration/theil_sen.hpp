#pragma once
/// Theil-Sen lines through short series of 3-vectors (a velocity model's rates, a trajectory's
/// positions): per axis the slope is the median of the pairwise slopes and the line's value the
/// median of the points moved along it, so a wrong point or two, which would tilt a least-squares
/// line most at the end of the series, leaves the line where the others put it.
#include <Eigen/Core>
#include <vector>

namespace planeslam::registration {

struct TheilSenLine {
  Eigen::Vector3d value = Eigen::Vector3d::Zero();  ///< at the fit's origin
  Eigen::Vector3d slope = Eigen::Vector3d::Zero();  ///< per unit of t
  bool valid = false;  ///< false without two points more than 1e-9 apart in t
};

/// Median of a non-empty list (the mean of the two middle values for an even count); reorders it.
double Median(std::vector<double>* values);
/// The middle value of a non-empty list, the larger of the two middle ones for an even count;
/// reorders it.
double UpperMedian(std::vector<double>* values);

/// The line through (t_k, x_k), its value taken at t = `origin`.
TheilSenLine FitTheilSenLine(const std::vector<double>& t, const std::vector<Eigen::Vector3d>& x,
                             double origin);

}  // namespace planeslam::registration
