// GBRG stage 5: each plane refitted from its pixels, and the pixel labels.
#include <algorithm>
#include <cmath>
#include <type_traits>

#include "grid_pipeline.hpp"

namespace planeslam::detection::gbrg {
namespace {

/// The final fit's buffers, reused across frames.
struct FinalFitWork {
  std::vector<std::int32_t> row_labels;  ///< one row of grid values expanded to pixels
  std::vector<std::int32_t> grid_ids;    ///< each grid's plane id (pixel labels = their grid's)
};

}  // namespace

// Each band of k rows is written once: a row of grid values expanded to pixels, appended once
// for every row of the band; then the invalid pixels of the grids with a value >= 0 are set to -1
// (listed by the moments pass: few of them have a value). Appended, not resized and overwritten:
// resizing fills the whole image with zeros first, a second pass over it. The row is filled with
// the grid size known at compile time where it is 3 or 6 (GBRG's 3x3 and 6x6 grids).
void ExpandToPixels(const GridImage& image, const CellMoments& cells,
                    const std::int32_t* grid_values, std::vector<std::int32_t>& pixels) {
  const int k = image.k, width = image.width, height = image.height;
  std::vector<std::int32_t>& row = internal::ThreadScratch<FinalFitWork>().row_labels;
  pixels.clear();
  pixels.reserve(static_cast<std::size_t>(width) * height);
  row.resize(width);
  std::int32_t* const row_labels = row.data();
  const int whole = width / k;  // grids of k columns; one narrower may follow
  auto fill_whole_grids = [&](const std::int32_t* values, auto grid_size) {
    constexpr int kSize = decltype(grid_size)::value;
    for (int cx = 0; cx < whole; ++cx) {
      for (int j = 0; j < kSize; ++j) row_labels[cx * kSize + j] = values[cx];
    }
  };
  for (int cy = 0; cy < image.cells_y; ++cy) {
    const int y0 = cy * k, y1 = std::min(height, y0 + k);
    const std::int32_t* values = grid_values + static_cast<std::size_t>(cy) * image.cells_x;
    if (k == 3) {
      fill_whole_grids(values, std::integral_constant<int, 3>());
    } else if (k == 6) {
      fill_whole_grids(values, std::integral_constant<int, 6>());
    } else {
      for (int cx = 0; cx < whole; ++cx) std::fill_n(row_labels + cx * k, k, values[cx]);
    }
    if (whole < image.cells_x) std::fill(row_labels + whole * k, row_labels + width, values[whole]);
    for (int y = y0; y < y1; ++y) pixels.insert(pixels.end(), row.begin(), row.end());
  }
  for (const int c : cells.partly_valid) {
    if (grid_values[c] < 0) continue;
    const auto [cx, cy] = image.Xy(c);
    const int x0 = cx * k, x1 = std::min(width, x0 + k);
    const int y0 = cy * k, y1 = std::min(height, y0 + k);
    for (int y = y0; y < y1; ++y) {
      const std::size_t offset = static_cast<std::size_t>(y) * width;
      for (int x = x0; x < x1; ++x) {
        if (!std::isfinite(image.pts[offset + x].z())) pixels[offset + x] = -1;
      }
    }
  }
}

// With grid labels the segmentation comes out with a plane id per grid, expanded to the pixels
// here, with the pixels whose label differs from their grid's set after.
void FinalFit(const GridImage& image, const CellMoments& cells, bool grid_labels,
              std::vector<std::int32_t>& region_image, Regions& regions,
              const internal::RegionBorders& borders, const GridFits* fits,
              const std::vector<std::int32_t>& label_root, Segmentation& out) {
  const std::vector<MomentSums>* fit_sums = nullptr;
  const std::vector<RaySums>* fit_rays = nullptr;
  if (grid_labels) {
    fit_sums = fits ? &fits->sums : &regions.sums;
    fit_rays = fits ? &fits->rays : &regions.rays;
  }
  internal::FinalizeSegmentation(image.cloud, region_image, regions.sums, regions.rays,
                                 borders.pixels, image.params, out, fit_sums, fit_rays, label_root);
  if (!grid_labels) return;
  // out.labels holds each grid's plane id: expand it to the pixels.
  std::vector<std::int32_t>& grid_ids = internal::ThreadScratch<FinalFitWork>().grid_ids;
  grid_ids.swap(out.labels);
  ExpandToPixels(image, cells, grid_ids.data(), out.labels);
  if (!fits) return;
  for (const auto& [i, grid] : fits->pixel_overrides) {
    out.labels[i] = grid >= 0 ? grid_ids[grid] : -1;
  }
}

}  // namespace planeslam::detection::gbrg
