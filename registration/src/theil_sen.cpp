#include "planeslam/registration/theil_sen.hpp"

#include <algorithm>
#include <cmath>
#include <cstddef>

namespace planeslam::registration {

double UpperMedian(std::vector<double>* values) {
  const auto middle = values->begin() + static_cast<std::ptrdiff_t>(values->size() / 2);
  std::nth_element(values->begin(), middle, values->end());
  return *middle;
}

double Median(std::vector<double>* values) {
  const double upper = UpperMedian(values);
  if (values->size() % 2 == 1) return upper;
  // UpperMedian left the lower half before the middle.
  const auto middle = values->begin() + static_cast<std::ptrdiff_t>(values->size() / 2);
  return 0.5 * (upper + *std::max_element(values->begin(), middle));
}

TheilSenLine FitTheilSenLine(const std::vector<double>& t, const std::vector<Eigen::Vector3d>& x,
                             double origin) {
  TheilSenLine line;
  std::vector<double> values;
  for (int axis = 0; axis < 3; ++axis) {
    values.clear();
    for (std::size_t i = 0; i < t.size(); ++i) {
      for (std::size_t j = i + 1; j < t.size(); ++j) {
        if (std::abs(t[j] - t[i]) > 1e-9)
          values.push_back((x[j](axis) - x[i](axis)) / (t[j] - t[i]));
      }
    }
    if (values.empty()) return line;
    line.slope(axis) = Median(&values);
    values.clear();
    for (std::size_t i = 0; i < t.size(); ++i) {
      values.push_back(x[i](axis) - line.slope(axis) * (t[i] - origin));
    }
    line.value(axis) = Median(&values);
  }
  line.valid = true;
  return line;
}

}  // namespace planeslam::registration
