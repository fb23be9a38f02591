// GBRG stage 4: where regions meet, and the regions describing one surface merged.
#include <algorithm>

#include "grid_pipeline.hpp"

namespace planeslam::detection::gbrg {

// The borders are scanned at the edge grids only: an interior grid holds one label and so no
// border.
internal::RegionBorders MergeRegions(const GridImage& image, const EdgeGrids& edges,
                                     bool grid_labels, std::vector<std::int32_t>& region_image,
                                     Regions& regions, std::vector<std::int32_t>& label_root) {
  const DetectionParams& params = image.params;
  const int k = image.k, width = image.width, height = image.height;
  internal::RegionBorders borders;
  if (params.merge_regions || (params.ray_fit && !grid_labels)) {
    internal::RegionBorderScan scan(region_image, grid_labels ? image.cells_x : width,
                                    grid_labels ? image.cells_y : height);
    const std::size_t num_edge = edges.grids.size();
    for (std::size_t e = 0; e < num_edge; ++e) {
      const int c = edges.grids[e];
      const auto [cx, cy] = image.Xy(c);
      if (grid_labels) {
        scan.Scan(cx, cy, cx + 1, cy + 1);
        continue;
      }
      // The label image (megabytes) has left the core's caches since the refinement wrote it:
      // fetch the rows the scan of a grid a few places ahead reads (its k rows and the rows
      // above and below).
      if (e + kRefinePrefetchAhead < num_edge) {
        const auto [ax, ay] = image.Xy(edges.grids[e + kRefinePrefetchAhead]);
        const int ry0 = std::max(0, ay * k - 1), ry1 = std::min(height, ay * k + k + 1);
        for (int y = ry0; y < ry1; ++y) {
          __builtin_prefetch(region_image.data() + static_cast<std::size_t>(y) * width + ax * k);
        }
      }
      scan.Scan(cx * k, cy * k, std::min(width, (cx + 1) * k), std::min(height, (cy + 1) * k));
    }
    borders = scan.Finish();
  }
  label_root.clear();
  if (params.merge_regions) {
    // A pixel image's relabelling waits for the plane ids (one pass for both); a grid image, which
    // the fits of the grid-level pipeline read, is relabelled now.
    internal::MergeCoplanarRegions(region_image, borders.pairs, regions.sums, regions.rays, params,
                                   grid_labels ? nullptr : &label_root);
  }
  return borders;
}

}  // namespace planeslam::detection::gbrg
