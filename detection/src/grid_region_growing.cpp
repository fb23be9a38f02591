#include "planeslam/detection/grid_region_growing.hpp"

#include <chrono>
#include <utility>
#include <vector>

#include "grid_pipeline.hpp"
#include "planeslam/datasets/errors.hpp"

namespace planeslam::detection {
namespace {

using Clock = std::chrono::steady_clock;
double Ms(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

/// What one stage hands to the next, reused across frames (no allocation per frame once warmed
/// up); each stage keeps its own scratch buffers as well.
struct Workspace {
  gbrg::CellMoments cells;
  gbrg::Regions regions;
  gbrg::EdgeGrids edges;
  std::vector<std::int32_t> labels;  ///< pixel labels (pixel-level refinement)
  std::vector<std::int32_t> label_root;
  gbrg::GridFits fits;
};

}  // namespace

std::vector<std::string> GridParams::Validate() const {
  std::vector<std::string> problems;
  if (cell_size != 0 && (cell_size < 2 || cell_size > 32))
    problems.push_back("cell_size must be 0 (automatic) or in [2, 32]");
  if (mu < 0 || mu > CellSize() * CellSize())
    problems.push_back("mu must be in [0, cell_size^2] (0 = automatic)");
  if (EffectiveMu() < 3) problems.push_back("mu must be >= 3 (a plane needs 3 points)");
  if (!(alpha > 0 && alpha < 1)) problems.push_back("alpha must be in (0, 1)");
  if (!(beta > 0 && beta < 1)) problems.push_back("beta must be in (0, 1)");
  if (refit_interval < 0) problems.push_back("refit_interval must be >= 0 (0 = adaptive)");
  return problems;
}

void UseFastVariant(DetectionParams& params, GridParams& grid) {
  grid.grid_level = true;
  params.refine_boundary = false;
}

GridRegionGrowing::GridRegionGrowing(const DetectionParams& params, const GridParams& grid,
                                     std::string name)
    : params_(params), grid_(grid), name_(std::move(name)) {
  auto problems = params_.Validate();
  auto more = grid_.Validate();
  problems.insert(problems.end(), more.begin(), more.end());
  PLANESLAM_CHECK(problems.empty(), "invalid GBRG parameters: " << problems.front());
  if (name_.empty()) name_ = "grid" + std::to_string(grid_.CellSize());
}

Segmentation GridRegionGrowing::Detect(const datasets::OrganizedCloud& cloud) const {
  Segmentation out;
  PLANESLAM_CHECK(cloud.points.size() == static_cast<std::size_t>(cloud.width) * cloud.height,
                  "organized cloud size mismatch");
  const gbrg::GridImage image(cloud, params_, grid_);
  out.width = image.width;
  out.height = image.height;
  out.cells_x = image.cells_x;
  out.cells_y = image.cells_y;
  out.cell_size = image.k;
  if (image.num_cells == 0) return out;
  Workspace& ws = internal::ThreadScratch<Workspace>();
  // Without the pixel-level refinement every valid pixel keeps its grid's label (the ray fit then
  // moves no pixel at a crease either): region borders, merging and plane ids are worked out on
  // the grid image (k^2 times fewer labels), and the pixel labels written once, at the end.
  const bool grid_labels = !params_.refine_boundary;
  const bool grid_fits = grid_labels && grid_.grid_level;

  const auto t0 = Clock::now();
  const double classify_ms = gbrg::ComputeCellMoments(image, ws.cells);
  const auto t1 = Clock::now();
  gbrg::GrowRegions(image, ws.cells, ws.regions);
  const auto t2 = Clock::now();
  gbrg::FindEdgeGrids(image, ws.cells, ws.regions.cell_region, ws.edges);
  if (grid_.grid_level) gbrg::RefineGrids(image, ws.cells, ws.regions, ws.edges);
  if (!grid_labels) gbrg::ExpandToPixels(image, ws.cells, ws.regions.cell_region.data(), ws.labels);
  gbrg::SumRegionRays(image, ws.cells, ws.regions);
  if (params_.refine_boundary && !ws.regions.sums.empty()) {
    gbrg::RefinePixels(image, ws.cells, ws.edges, ws.regions, ws.labels);
  }
  const auto t3 = Clock::now();
  std::vector<std::int32_t>& region_image = grid_labels ? ws.regions.cell_region : ws.labels;
  const internal::RegionBorders borders =
      gbrg::MergeRegions(image, ws.edges, grid_labels, region_image, ws.regions, ws.label_root);
  if (grid_fits) gbrg::FitGridPlanes(image, ws.cells, ws.edges, ws.regions, ws.fits);
  gbrg::FinalFit(image, ws.cells, grid_labels, region_image, ws.regions, borders,
                 grid_fits ? &ws.fits : nullptr, ws.label_root, out);
  out.cell_classes = ws.cells.classes;
  const auto t4 = Clock::now();
  out.timings_ms = {{"moments", Ms(t0, t1) - classify_ms},
                    {"classify", classify_ms},
                    {"grow", Ms(t1, t2)},
                    {"refine", Ms(t2, t3)},
                    {"finalize", Ms(t3, t4)}};
  return out;
}

}  // namespace planeslam::detection
