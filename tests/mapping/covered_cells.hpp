#pragma once
// Test helper: the area a hole-free outline of a seen region should cover. Map outlines have no
// holes (a part of a wall hidden behind a box lies inside its outline), so the seen cells of a
// plane count together with the unseen cells they enclose.
#include <algorithm>
#include <cstddef>
#include <set>
#include <utility>
#include <vector>

namespace planeslam::test {

/// Cells of a w x h grid (row-major `seen`, index i * h + j for cell (i, j)) that are seen or
/// enclosed by seen cells: all but the unseen cells connected (4-neighbours) to the border.
inline std::size_t CoveredCells(const std::vector<bool>& seen, int w, int h) {
  std::vector<bool> outside(seen.size(), false);
  std::vector<std::pair<int, int>> stack;
  auto push = [&](int i, int j) {
    if (i < 0 || j < 0 || i >= w || j >= h) return;
    const std::size_t k = static_cast<std::size_t>(i) * h + j;
    if (seen[k] || outside[k]) return;
    outside[k] = true;
    stack.emplace_back(i, j);
  };
  for (int i = 0; i < w; ++i) {
    push(i, 0);
    push(i, h - 1);
  }
  for (int j = 0; j < h; ++j) {
    push(0, j);
    push(w - 1, j);
  }
  while (!stack.empty()) {
    const auto [i, j] = stack.back();
    stack.pop_back();
    push(i + 1, j);
    push(i - 1, j);
    push(i, j + 1);
    push(i, j - 1);
  }
  std::size_t covered = 0;
  for (bool o : outside) covered += o ? 0 : 1;
  return covered;
}

/// Cells (of some size) of a plane's 2D coordinates.
using CellSet = std::set<std::pair<int, int>>;

/// Area of the cells with their holes filled [m^2] (map outlines have no holes).
inline double FilledArea(const CellSet& cells, double cell) {
  if (cells.empty()) return 0.0;
  int u0 = cells.begin()->first, u1 = u0, v0 = cells.begin()->second, v1 = v0;
  for (const auto& [u, v] : cells) {
    u0 = std::min(u0, u);
    u1 = std::max(u1, u);
    v0 = std::min(v0, v);
    v1 = std::max(v1, v);
  }
  const int w = u1 - u0 + 1, h = v1 - v0 + 1;
  std::vector<bool> seen(static_cast<std::size_t>(w) * h, false);
  for (const auto& [u, v] : cells) seen[static_cast<std::size_t>(u - u0) * h + (v - v0)] = true;
  return static_cast<double>(CoveredCells(seen, w, h)) * cell * cell;
}

}  // namespace planeslam::test
