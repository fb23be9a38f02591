#include "planeslam/detection/grid_region_growing.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <functional>
#include <tuple>
#include <type_traits>
#include <utility>
#include <vector>

#include "planeslam/datasets/errors.hpp"
#include "region_common.hpp"

namespace planeslam::detection {
namespace {

using Clock = std::chrono::steady_clock;
double Ms(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

/// Plane of one planar grid and its per-grid test tolerances, in float: 32 bytes, half a cache
/// line (the growth reads one per tested grid, in an order that leaves the cache often). Float
/// places the centre to a micrometre at 10 m, against tolerances of millimetres.
struct alignas(32) CellInfo {
  Eigen::Vector3f n = Eigen::Vector3f::Zero();  ///< oriented unit normal (d >= 0)
  Eigen::Vector3f m = Eigen::Vector3f::Zero();  ///< mass centre [m]
  float cos_tol = 1.0f;  ///< eta test: |n_GR . n_g| must exceed this (-1 = no test)
  float sin_tol = 0.0f;  ///< sine of the same tolerance (widening it by a tilt needs both)
};

/// Growth mark of a grid that can no longer join a region (see Workspace::mark).
constexpr std::int32_t kTaken = -2;

/// Grids classified per batch (the batch arrays of a chunk take about 130 kB).
constexpr int kClassifyChunk = 1024;

/// How many queue places ahead the growth prefetches grid data.
constexpr std::size_t kPrefetchAhead = 6;
/// How many edge grids ahead the refinement prefetches their points.
constexpr std::size_t kRefinePrefetchAhead = 4;

/// Per-thread buffers reused across frames (no allocation per frame once warmed up).
struct Workspace {
  std::vector<MomentSums> sums;
  std::vector<double> noise_weight;  ///< each grid's w = (sigma(z) / z)^2 at its centre
  std::vector<std::int32_t> counts;  ///< each grid's valid pixels (its K, compact for scans)
  std::vector<int> partly_valid;     ///< the grids with an invalid pixel, ascending
  std::vector<CellClass> classes;
  std::vector<int> dense;                   ///< the non-sparse grids of a classification chunk
  std::vector<double> scatter[6];           ///< their scatter, one array per entry
  std::vector<double> l1, l2, l3;           ///< their eigenvalues, ascending
  std::vector<double> v1[3];                ///< their smallest eigenvectors
  std::vector<double> l1_refined;           ///< l1 as the Rayleigh quotient of v1
  std::vector<double> eigen_ok;             ///< 0: l1..l3 to come from the closed form
  std::vector<double> dense_k, dense_w[6];  ///< their K and noise moment W (GridNoiseBatch)
  std::vector<double> isotropic, tilt, effective, angle;  ///< GridNoiseBatch's figures of them
  std::vector<CellInfo> info;
  std::vector<std::int32_t> cell_region;
  /// Growth state of each grid, one load per look: kTaken (not planar, or in R or R'), else the
  /// last region that queued it (-1: none yet).
  std::vector<std::int32_t> mark;
  std::vector<int> queue;
  std::vector<int> members;
  std::vector<std::uint64_t> seeds;
  std::vector<std::uint64_t> seed_keys;  ///< each planar grid's seed key (regrow_left_out)
  std::vector<int> left_out;             ///< the grids of R' after the first growth (ditto)
  std::vector<std::uint8_t> region_fitted;  ///< whether fits holds a plane's fit yet (ditto)
  std::vector<MomentSums> regions;
  std::vector<FastFit> fits;
  std::vector<float> plane_nd;  ///< each region's n, d in float (pixel-level refinement)
  std::vector<std::pair<std::size_t, int>> moved_pixels;  ///< of one edge grid (ditto)
  std::vector<std::int32_t> labels;
  std::vector<std::int32_t> row_labels;  ///< one row of grid labels expanded to pixels
  std::vector<RaySums> grid_rays;        ///< ray sums of each grid's pixels (ray fit)
  std::vector<RaySums> rays;             ///< ray sums of each region
  std::vector<int> edge_grids;           ///< grids with a neighbour outside their region
  std::vector<int> edge_scratch;         ///< edge grids as found (room for every grid)
  std::vector<std::uint8_t> edge_flags;  ///< whether each grid of a row is an edge grid
  std::vector<MomentSums> fit_sums;      ///< what each plane is fitted to (whole grids)
  std::vector<RaySums> fit_rays;
  std::vector<std::uint8_t> narrow;    ///< 1: too narrow for the interior fit; 2: refined anyway
  std::vector<MomentSums> apart_sums;  ///< such a plane without its grids next to another plane
  std::vector<RaySums> apart_rays;
  std::vector<std::uint8_t> too_narrow;     ///< planes too narrow for the apart fit as well
  std::vector<std::uint8_t> refine_pixels;  ///< those of them refined pixel by pixel
  std::vector<std::pair<int, int>> narrow_plane_grids;  ///< (such a plane, one of its grids)
  std::vector<int> narrow_grids;                        ///< the grids of one such plane
  std::vector<int> narrow_around;                       ///< the grids around them
  std::vector<int> visit;       ///< per grid: the last such plane it was found around (-1: none)
  std::vector<int> candidates;  ///< the plane and the planes next to it
  std::vector<int> candidate_grid;      ///< a grid of each (for its plane id)
  std::vector<float> candidate_planes;  ///< n, d of each (best_plane_for_pixel)
  /// Moves of the pixel-level refinement of such a plane: (pixel, its grid, candidate it goes
  /// to: 0 the plane itself, -1 none).
  std::vector<std::tuple<std::size_t, int, int>> narrow_moves;
  std::vector<std::tuple<std::size_t, int, int>> narrow_choices;  ///< refine_narrow_plane's
  std::vector<internal::RayPlane> candidate_ray_planes;           ///< refine_narrow_plane's
  /// Pixel labels that differ from their grid's: (pixel, a grid of their plane, or -1: none).
  std::vector<std::pair<std::size_t, int>> pixel_overrides;
  std::vector<std::int32_t> grid_ids;  ///< each grid's plane id (pixel labels = their grid's)
  std::vector<std::pair<int, int>> grid_moves;  ///< (grid, region) of the grid-level refinement
  std::vector<std::uint8_t> fit_stale;          ///< per region: fits[r] is out of date
  std::vector<float> block_ratio;               ///< refine_narrow_plane's, per candidate
  std::vector<double> edge_points;              ///< per region: the points of its edge grids
  std::vector<std::uint8_t> is_narrow;          ///< per region (narrow_passes)
  std::vector<std::uint8_t> at_narrow_plane;    ///< per grid: in or next to a narrow plane (ditto)
  std::vector<std::int32_t> label_root;         ///< the merge's label -> region map (pixel labels)
  std::vector<std::int32_t> candidate_stamp;    ///< per region (+1): last edge grid it was seen at
};

// The grid-level pipeline's constants (GridParams::grid_level).
// A growing region whose second-smallest spread l2 / K is within this many times its ray noise
// has no resolved normal yet: on a far wall, where the noise exceeds a grid's width, a strip of
// grids fits a plane across the strip, so such a region joins grids by the MSE test alone.
constexpr double kUnresolvedSpread = 2.0;
// More passes of the grid-level refinement at narrow planes, while grids move: one pass judges a
// plane's neighbour grids against its fit as grown, which a few grids of the wall behind it can
// tilt; each pass refits and judges again.
constexpr int kNarrowPasses = 3;
// The smallest narrow plane [points] refined pixel by pixel; smaller ones are mostly slivers of a
// neighbouring plane, which keep whole grids.
constexpr double kNarrowRefinePoints = 2000.0;

Workspace& ThreadWorkspace() {
  thread_local Workspace ws;
  return ws;
}

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
  const int width = cloud.width, height = cloud.height;
  PLANESLAM_CHECK(cloud.points.size() == static_cast<std::size_t>(width) * height,
                  "organized cloud size mismatch");
  const int k = grid_.CellSize();
  const int cells_x = (width + k - 1) / k, cells_y = (height + k - 1) / k;
  const int num_cells = cells_x * cells_y;
  // A grid's column and row without an integer division (tens of cycles, in the per-grid loops of
  // growth and refinement): (c + 0.5) / cells_x is at least 0.5 / cells_x from an integer, far
  // beyond its rounding.
  const double inv_cells_x = 1.0 / std::max(cells_x, 1);
  auto grid_xy = [inv_cells_x, cells_x](int c) {
    const int cy = static_cast<int>((c + 0.5) * inv_cells_x);
    return std::pair<int, int>(c - cy * cells_x, cy);
  };
  out.width = width;
  out.height = height;
  out.cells_x = cells_x;
  out.cells_y = cells_y;
  out.cell_size = k;
  if (num_cells == 0) return out;
  const bool spherical = cloud.model == datasets::SensorModel::kSpherical;
  const bool depth_model = params_.model == ThresholdModel::kDepth;
  const Eigen::Vector3f* pts = cloud.points.data();
  Workspace& ws = ThreadWorkspace();

  // ---- 1. Per-grid moments: K, S, Q (10 sums) and the ray sums of a row of grids at a time,
  // while its band of k image rows is in L1 (the final ray fit of a region then adds its grids'
  // sums instead of visiting every pixel again); then each grid's noise moment W. Step 2 runs on
  // each row of grids right after, while its sums are still in cache (3x3 grids: 34k grids, 4.4 MB
  // of sums; classify 2.39 -> 1.96 ms, moments unchanged, in 16 alternating runs on TUM frames).
  const auto t0 = Clock::now();
  ws.sums.resize(num_cells);
  ws.noise_weight.resize(num_cells);  // written for every grid below
  ws.counts.resize(num_cells);
  ws.grid_rays.resize(params_.ray_fit ? num_cells : 0);
  ws.partly_valid.resize(num_cells);
  std::size_t num_partly_valid = 0;
  const SimdKernel kernel = FastestSimdKernel();
  const double s0 = params_.sigma0, s2 = params_.sigma_z2;

  // ---- 2. Shape classification (Section III-A) and the planar grids' planes, of the grids in
  // [begin, end).
  const double mu = grid_.EffectiveMu();
  // The least points of a non-sparse grid at grid column cx, row cy: mu, or with border_grid_mu,
  // mu scaled by the share of a k x k grid that a grid cut by the image border covers.
  auto mu_of = [&](int cx, int cy) {
    if (!grid_.grid_level) return mu;
    const int w = std::min(k, width - cx * k), h = std::min(k, height - cy * k);
    return std::max(3.0, std::ceil(mu * w * h / (k * k)));
  };
  const double eta = params_.eta_deg * M_PI / 180.0;
  const double cos_eta = std::cos(eta);
  ws.classes.assign(num_cells, CellClass::kSparse);
  ws.info.resize(num_cells);
  ws.seeds.clear();
  if (grid_.grid_level) ws.seed_keys.resize(num_cells);
  // Seed key: the MSE as a float's bit pattern (monotonic for non-negative floats) above the grid
  // index, so one sort of 64-bit keys gives the order a min-heap of (MSE, index) would pop.
  auto seed_key = [](double mse, int c) {
    const float f = static_cast<float>(std::max(mse, 0.0));
    std::uint32_t bits;
    std::memcpy(&bits, &f, 4);
    return static_cast<std::uint64_t>(bits) << 32 | static_cast<std::uint32_t>(c);
  };
  // The non-sparse grids in chunks of kClassifyChunk, whose batch arrays stay in cache: per
  // chunk the grids' scatter, then their eigenvalues all at once (the batch keeps the divisions of
  // many grids in flight), their eigenvectors, and the rules.
  ws.dense.resize(kClassifyChunk);
  for (auto& column : ws.scatter) column.resize(kClassifyChunk);
  for (auto* l : {&ws.l1, &ws.l2, &ws.l3, &ws.eigen_ok, &ws.l1_refined, &ws.dense_k, &ws.isotropic,
                  &ws.tilt, &ws.effective, &ws.angle}) {
    l->resize(kClassifyChunk);
  }
  for (auto& column : ws.v1) column.resize(kClassifyChunk);
  for (auto& column : ws.dense_w) column.resize(kClassifyChunk);
  // classify runs on one row of grids at a time: its mu, and that of its last grid.
  auto classify = [&](int begin, int end) {
    const int cy = grid_xy(begin).second;
    const double row_mu = mu_of(0, cy), last_mu = mu_of(cells_x - 1, cy);
    for (int next = begin; next < end;) {
      // The non-sparse grids listed without a branch per grid (which ones are is data).
      int num_dense = 0;
      int* const dense = ws.dense.data();
      for (; next < end && num_dense < kClassifyChunk; ++next) {
        dense[num_dense] = next;
        num_dense += ws.counts[next] >= (next + 1 == end ? last_mu : row_mu);  // else sparse
      }
      for (int j = 0; j < num_dense; ++j) {
        const MomentSums& s = ws.sums[ws.dense[j]];
        double scatter[6];
        s.Scatter(scatter);
        for (int i = 0; i < 6; ++i) ws.scatter[i][j] = scatter[i];
        ws.dense_k[j] = s.k;
        const double w[6] = {s.wxx, s.wxy, s.wxz, s.wyy, s.wyz, s.wzz};
        for (int i = 0; i < 6; ++i) ws.dense_w[i][j] = w[i];
      }
      // A grid's eigenvalues feed thresholds and a float seed key: Newton's last step below 1e-9 of
      // the trace is plenty (a grid whose normal is read refines l1 as its Rayleigh quotient
      // anyway). Lanes where it is not reached in eight steps (l1 close to l2) use the closed form.
      const double* columns[6];
      for (int i = 0; i < 6; ++i) columns[i] = ws.scatter[i].data();
      SymEigenvaluesNewtonBatch(columns, num_dense, 1e-9, ws.l1.data(), ws.l2.data(), ws.l3.data(),
                                ws.eigen_ok.data(), kernel);
      for (int j = 0; j < num_dense; ++j) {
        if (ws.eigen_ok[j]) continue;
        double scatter[6];
        for (int i = 0; i < 6; ++i) scatter[i] = ws.scatter[i][j];
        SymEigenvalues3(scatter, ws.l1[j], ws.l2[j], ws.l3[j]);
      }
      // Every grid's smallest eigenvector, also in one batch (read only where the normal counts).
      double* const v1[3] = {ws.v1[0].data(), ws.v1[1].data(), ws.v1[2].data()};
      SmallestEigenvectorBatch(columns, ws.l1.data(), ws.l2.data(), ws.l3.data(), num_dense, v1,
                               ws.l1_refined.data(), kernel);
      // The noise figures the rules below branch on, also in one batch (read only where they
      // count). The rules took 0.92 ms a TUM frame with their divisions and square roots, which
      // the branches waited on.
      const double* const w[6] = {ws.dense_w[0].data(), ws.dense_w[1].data(), ws.dense_w[2].data(),
                                  ws.dense_w[3].data(), ws.dense_w[4].data(), ws.dense_w[5].data()};
      const double* const normals[3] = {v1[0], v1[1], v1[2]};
      GridNoiseBatch(ws.dense_k.data(), w, ws.l2.data(), normals, num_dense, eta,
                     params_.eta_sigmas, ws.isotropic.data(), ws.tilt.data(), ws.effective.data(),
                     ws.angle.data(), kernel);
      for (int j = 0; j < num_dense; ++j) {
        const int c = ws.dense[j];
        const MomentSums& s = ws.sums[c];
        SymEigen3 e;
        e.l1 = ws.l1[j];
        e.l2 = ws.l2[j];
        e.l3 = ws.l3[j];
        if (e.l2 <= grid_.alpha * e.l3) {
          ws.classes[c] = CellClass::kLinear;
          continue;
        }
        const double iso = ws.isotropic[j];
        // The eigenvector only where it counts: the noise along the normal of a grid whose normal
        // is pure noise (tilt >= 1, most grids beyond 2-3 m) is its isotropic noise, and such a
        // grid gets no angle test either (see below).
        double tilt = ws.tilt[j];
        // A grid no flatter than its own noise (l1 beyond the paper's beta l2, and a residual
        // within the full ray noise) has a normal that is noise too, whatever l2 says: a large grid
        // far away, whose lateral extent is below the depth noise, and whose smallest eigenvector
        // then lies in the image plane. Its normal is treated as unknown, as that of a grid tilted
        // by a radian or more.
        if (depth_model && tilt < 1.0 && e.l1 > grid_.beta * e.l2 &&
            e.l1 / s.k <= params_.planar_sigmas * params_.planar_sigmas * iso) {
          tilt = 1.0;
        }
        const bool have_normal = !depth_model || tilt < 1.0;
        if (have_normal) {  // the eigenvector, and l1 refined as its Rayleigh quotient
          e.v1 = Eigen::Vector3d(ws.v1[0][j], ws.v1[1][j], ws.v1[2][j]);
          e.l1 = ws.l1_refined[j];
        }
        const double mse = e.l1 / s.k;
        // sigma_n,rms^2 (where have_normal holds, tilt is still the batch's, and so is the
        // effective MSE with it)
        const double noise_mse = have_normal ? ws.effective[j] : iso;
        bool planar = e.l1 <= grid_.beta * e.l2;
        if (!planar && depth_model) {
          planar = mse <= params_.planar_sigmas * params_.planar_sigmas * noise_mse;
        }
        if (!planar) {
          ws.classes[c] = CellClass::kSpherical;
          continue;
        }
        ws.classes[c] = CellClass::kPlanar;
        CellInfo& ci = ws.info[c];
        const Eigen::Vector3d centre = s.Centroid();
        ci.m = centre.cast<float>();
        if (depth_model) {
          // Normal noise of a small grid: std ~ sigma_n / sqrt(l2) [rad], from noise_mse (read
          // only where have_normal holds).
          const double ang = ws.angle[j];
          if (ang >= 0.5 * M_PI || !have_normal) {
            ci.n.setZero();  // no angle test: the growth never reads it
            ci.cos_tol = -1.0f;
            ci.sin_tol = 1.0f;
          } else {
            ci.n = (e.v1.dot(centre) < 0 ? Eigen::Vector3d(-e.v1) : e.v1).cast<float>();
            double sin_ang, cos_ang;
            SinCosFirstQuadrant(ang, sin_ang, cos_ang);  // eta <= ang < pi / 2
            ci.cos_tol = static_cast<float>(cos_ang);
            ci.sin_tol = static_cast<float>(sin_ang);
          }
          // Seed order under the noise model: the paper's minimal MSE, plus the ray noise leaking
          // in through the grid's normal uncertainty, so that grids whose normal is mostly noise
          // (far away, where a fluke can give a tiny MSE with a random normal) seed last.
          const double seed_tilt = std::min(1.0, tilt);
          ws.seeds.push_back(seed_key(mse + iso * seed_tilt * seed_tilt, c));
          if (grid_.grid_level) ws.seed_keys[c] = ws.seeds.back();
        } else {
          ci.n = (e.v1.dot(centre) < 0 ? Eigen::Vector3d(-e.v1) : e.v1).cast<float>();
          ci.cos_tol = static_cast<float>(cos_eta);
          ws.seeds.push_back(seed_key(mse, c));  // Algorithm 2 line 4: minimal MSE first
          if (grid_.grid_level) ws.seed_keys[c] = ws.seeds.back();
        }
      }
    }
  };

  double classify_ms = 0.0;  // step 2's share of the loop, for the stage timings
  for (int cy = 0; cy < cells_y; ++cy) {
    const int y0 = cy * k, y1 = std::min(height, y0 + k);
    const std::size_t row = static_cast<std::size_t>(cy) * cells_x;
    const bool last_row = cy + 1 == cells_y;
    const std::size_t next_row = row + cells_x;
    SumGridRow(pts, width, height, y0, y1, k, spherical, params_, ws.sums.data() + row,
               params_.ray_fit ? ws.grid_rays.data() + row : nullptr, kernel,
               last_row ? nullptr : ws.sums.data() + next_row,
               params_.ray_fit && !last_row ? ws.grid_rays.data() + next_row : nullptr);
    for (std::size_t c = row; c < row + cells_x; ++c) {
      MomentSums& m = ws.sums[c];
      ws.counts[c] = static_cast<std::int32_t>(m.k);
      // Listed without a branch (the pixel labels mark their invalid pixels, expand_to_pixels).
      const int x0 = static_cast<int>(c - row) * k;
      const int pixels = (std::min(width, x0 + k) - x0) * (y1 - y0);
      ws.partly_valid[num_partly_valid] = static_cast<int>(c);
      num_partly_valid += m.k < pixels;
      if (m.k == 0) {
        ws.noise_weight[c] = 0.0;
        continue;
      }
      // Noise moment: W = w(z) Q with w = (sigma(z)/z)^2 at the grid's centre (within a k x k
      // grid z varies by ~1 %, so this equals the per-pixel sum to ~2 %; the pixels the
      // refinement moves carry their grid's weight too).
      const double z = spherical ? m.Centroid().norm() : m.sz / m.k;
      const double w = z > 0 ? (s0 + s2 * z * z) * (s0 + s2 * z * z) / (z * z) : 0.0;
      m.SetUniformNoise(w);
      ws.noise_weight[c] = w;
    }
    const auto tc = Clock::now();
    classify(static_cast<int>(row), static_cast<int>(row) + cells_x);
    classify_ms += Ms(tc, Clock::now());
  }

  ws.partly_valid.resize(num_partly_valid);

  // A grid's MSE about plane f in units of its tolerance there, refine_sigmas^2 times its
  // expected MSE along the normal (depth model) or gamma^2 (constant model): under 1, it fits.
  const double refine2 = params_.refine_sigmas * params_.refine_sigmas;
  auto grid_fit_ratio = [&](const MomentSums& g, const FastFit& f) {
    double nqn, ns;  // the grid's squared distances to the plane: nqn - 2 d ns + K d^2
    g.AlongNormal(f.normal, nqn, ns);
    const double mse = std::max(0.0, nqn - 2.0 * f.d * ns + g.k * f.d * f.d) / g.k;
    const double tolerance2 =
        depth_model ? refine2 * g.ExpectedMse(f.normal) : params_.gamma * params_.gamma;
    return mse / std::max(tolerance2, 1e-18);
  };

  // The region of the grid at column cx, row cy (-1: none, or outside the image).
  auto region_at = [&](int cx, int cy) {
    return cx >= 0 && cy >= 0 && cx < cells_x && cy < cells_y ? ws.cell_region[cy * cells_x + cx]
                                                              : -1;
  };

  // ---- 3. Region growing (Algorithm 2): seeds in order of grid MSE, BFS over 4-neighbours.
  const auto t2 = Clock::now();
  ws.cell_region.assign(num_cells, -1);
  ws.mark.resize(num_cells);
  for (int c = 0; c < num_cells; ++c) {
    ws.mark[c] = ws.classes[c] == CellClass::kPlanar ? -1 : kTaken;
  }
  ws.regions.clear();
  ws.left_out.clear();
  bool second_growth = false;                             // regrow_left_out's second pass
  const bool adaptive_refit = grid_.refit_interval != 1;  // else the paper's refit per join
  const std::size_t theta_grids = static_cast<std::size_t>((params_.theta + k * k - 1) / (k * k));
  // A grid is queued at most once for each neighbour that joins the region (then taken, or
  // rejected and free to be queued again): 4 per grid bounds a region's queue.
  ws.queue.resize(4 * static_cast<std::size_t>(num_cells) + 4);
  auto grow_from = [&](int seed) {
    const int r = static_cast<int>(ws.regions.size());
    MomentSums region = ws.sums[seed];
    FastFit fit = FitSums(region);
    // The region normal's own uncertainty (depth model), kept with the fit: the tilt [rad] and
    // its cosine and sine, which widen every grid's angle tolerance.
    double tilt = 0.0, cos_tilt = 1.0, sin_tilt = 0.0;
    // Whether the region's normal is resolved (grid.unresolved_spread): while its second-smallest
    // spread l2 / K is within unresolved_spread times its ray noise, the depth noise and the
    // region's narrow side are not told apart, and the fitted normal may lie in the surface
    // (a strip of grids on a far wall fits the plane across the strip, not the wall).
    bool normal_resolved = true;
    auto update_tilt = [&](double raw_tilt) {
      normal_resolved = !(fit.l2 < (grid_.grid_level ? kUnresolvedSpread : 0.0) * region.IsotropicMse() * region.k);
      tilt = std::min(1.0, raw_tilt);
      if (tilt > 0.02) {  // below, the tests ignore the tilt (see there)
        SinCosFirstQuadrant(tilt, sin_tilt, cos_tilt);  // 0.02 < tilt <= 1
      }
    };
    if (depth_model) update_tilt(region.NormalTilt(fit.l2));
    int since_refit = 0;  // joins since the plane was last refitted
    ws.members.clear();
    ws.members.push_back(seed);
    ws.cell_region[seed] = r;
    ws.mark[seed] = kTaken;
    // The queue in a buffer with room for every push (below), so a push needs no check.
    int* const queue = ws.queue.data();
    std::size_t head = 0, tail = 0;
    // Right, left, down, up, without a branch per neighbour (whether one is queued is data, not a
    // pattern): each is written to the queue's end, which advances only if it is queued; one
    // outside the image is c itself, which is taken.
    auto push_neighbours = [&](int c) {
      const auto [cx, cy] = grid_xy(c);
      const int neighbours[4] = {cx + 1 < cells_x ? c + 1 : c, cx > 0 ? c - 1 : c,
                                 cy + 1 < cells_y ? c + cells_x : c, cy > 0 ? c - cells_x : c};
      for (const int nb : neighbours) {
        // Not planar, in R, R' or this region; or queued already.
        const std::int32_t mark = ws.mark[nb];
        const bool queued = (mark != kTaken) & (mark != r);
        queue[tail] = nb;
        tail += queued;
        ws.mark[nb] = queued ? r : mark;
      }
    };
    push_neighbours(seed);
    while (head < tail) {
      const int g = queue[head++];
      if (ws.mark[g] == kTaken) continue;
      ws.mark[g] = -1;  // may be queued again by a later neighbour if rejected now
      // The wavefront of a large region spans more grids than the cache holds: fetch the data of
      // the grids a few places ahead in the queue while this one is tested. A grid's sums (128
      // bytes) lie across three cache lines unless the array happens to start on a line: all
      // three are fetched (grow stage, alternating runs: grid3 2.67 -> 2.42 ms, grid-fast 1.14 ->
      // 0.97 ms).
      if (head + kPrefetchAhead < tail) {
        const int ahead = queue[head + kPrefetchAhead];
        __builtin_prefetch(&ws.info[ahead]);
        __builtin_prefetch(&ws.sums[ahead]);
        __builtin_prefetch(reinterpret_cast<const char*>(&ws.sums[ahead]) + 64);
        __builtin_prefetch(reinterpret_cast<const char*>(&ws.sums[ahead]) + sizeof(MomentSums) - 1);
      }
      const CellInfo& ci = ws.info[g];
      // Algorithm 2 line 8: angle, coplanarity, then the merged MSE (the only one needing a fit).
      const MomentSums& gs = ws.sums[g];
      const Eigen::Vector3d diff = fit.centroid - ci.m.cast<double>();
      const Eigen::Vector3d grid_normal = ci.n.cast<double>();
      const double cos_tol = ci.cos_tol, sin_tol = ci.sin_tol;
      const double off = std::abs(fit.normal.dot(diff));
      if (depth_model && !normal_resolved) {
        // No angle or coplanarity test against an unresolved normal: the MSE test below (of the
        // merged fit, whatever its normal) decides alone, and the region grows across its narrow
        // side until the spread there exceeds the noise and the normal is the surface's.
      } else if (depth_model) {
        // A young region's own normal is uncertain (tilt, 2 sigma): widen the angle test by it
        // and let the coplanarity test allow tilt x lateral distance, so that a seed with a
        // noisy normal corrects itself by growing instead of growing a strip along its error.
        const double dot = std::abs(fit.normal.dot(grid_normal));
        if (tilt > 0.02) {
          // cos(tolerance + tilt); the sum stays below 3 pi / 2, so cos > 0 iff it is < pi / 2.
          const double cos_ang = cos_tol * cos_tilt - sin_tol * sin_tilt;
          if (cos_tol >= 0 && cos_ang > 0 && dot <= cos_ang) continue;
        } else if (dot <= cos_tol)
          continue;
        // The bound below is at least the base gamma, which admits most grids of a plane: only
        // the others pay for its square roots.
        if (off >= params_.gamma) {
          const double lateral = std::sqrt(std::max(0.0, diff.squaredNorm() - off * off));
          // Noise of the grid's centre along the region normal: sigma_n / sqrt(K_g).
          const double gamma =
              params_.Gamma(std::sqrt(gs.EffectiveMse(fit.normal, tilt) / gs.k)) + tilt * lateral;
          if (off >= gamma) continue;
        }
      } else {
        if (std::abs(fit.normal.dot(grid_normal)) <= cos_tol) continue;
        if (off >= params_.gamma) continue;
      }
      MomentSums merged = region;
      merged.Merge(gs);
      // The MSE test, with the cheap bound first: the noise along the normal alone is a lower
      // bound of the effective noise (its tilt term only adds), and the MSE about the current
      // normal an upper bound of the merged fit's, so either passing the test passes the exact one.
      if (adaptive_refit && MseAboutWithinEpsilon(merged, fit.normal, params_)) {
        region = merged;
        since_refit += 1;
        const int interval = grid_.refit_interval > 0
                                 ? grid_.refit_interval
                                 : std::max(1, static_cast<int>(ws.members.size()) / 64);
        if (since_refit >= interval) {
          fit = RefitFrom(region, fit.normal);
          if (depth_model) update_tilt(region.NormalTilt(fit.l2));
          since_refit = 0;
        }
      } else {
        const FastFit merged_fit = RefitFrom(merged, fit.normal);
        const double merged_tilt = merged.NormalTilt(merged_fit.l2);
        if (merged_fit.mse >= params_.Epsilon(merged.ExpectedMse(merged_fit.normal), merged.k)) {
          const double expected = merged.EffectiveMse(merged_fit.normal, merged_tilt);
          if (merged_fit.mse >= params_.Epsilon(expected, merged.k)) continue;
        }
        region = merged;
        fit = merged_fit;  // eq. (5): plane parameters updated on the join
        if (depth_model) update_tilt(merged_tilt);
        since_refit = 0;
      }
      ws.cell_region[g] = r;
      ws.mark[g] = kTaken;
      ws.members.push_back(g);
      push_neighbours(g);
    }
    if (ws.members.size() >= theta_grids) {
      ws.regions.push_back(region);
    } else {
      // R' (Algorithm 2 line 15): these grids leave G, as in the paper: they neither seed nor join
      // later regions (letting later regions re-grow into them made the growth quadratic on
      // cluttered scans). Boundary refinement may still give their pixels to a plane, and with
      // regrow_left_out they grow once more after all seeds (below).
      for (int c : ws.members) ws.cell_region[c] = -1;
      if (grid_.grid_level && !second_growth) {
        ws.left_out.insert(ws.left_out.end(), ws.members.begin(), ws.members.end());
      }
    }
  };
  // Seeds in key order. Most grids join one of the first regions, so instead of sorting every key
  // up front the keys are taken in chunks: the smallest chunk is selected (nth_element) and sorted,
  // its seeds are grown, and the keys of grids used meanwhile are dropped before the next chunk.
  // Keys are unique (grid index in the low bits), so the order is exactly that of a full sort.
  std::vector<std::uint64_t>& seeds = ws.seeds;
  std::size_t next = 0;
  while (next < seeds.size()) {
    // The keys of grids used meanwhile dropped, in order, without a branch per key (whether a
    // grid is taken is data, not a pattern).
    std::size_t kept = next;
    for (std::size_t i = next; i < seeds.size(); ++i) {
      const std::uint64_t key = seeds[i];
      seeds[kept] = key;
      kept += ws.mark[key & 0xffffffffu] != kTaken;
    }
    seeds.resize(kept);
    if (next >= seeds.size()) break;
    // The chunk: the keys below a threshold taken from a sample of the keys left, moved to the
    // front in one pass (std::partition; nth_element took two to three passes: the sort and
    // selection took 0.25 ms of a TUM frame with 3x3 grids). A sample key is itself a key left,
    // so at least the smallest sample key is below the threshold.
    const std::size_t remaining = seeds.size() - next;
    const std::size_t chunk = std::max<std::size_t>(256, remaining / 32);
    const auto first = seeds.begin() + static_cast<std::ptrdiff_t>(next);
    auto last = seeds.end();
    if (remaining > chunk) {
      constexpr std::size_t kSample = 64;
      std::uint64_t sample[kSample];
      for (std::size_t s = 0; s < kSample; ++s) sample[s] = first[s * remaining / kSample];
      std::sort(sample, sample + kSample);
      const std::uint64_t threshold =
          sample[std::clamp<std::size_t>(kSample * chunk / remaining, 1, kSample - 1)];
      last = std::partition(first, seeds.end(),
                            [threshold](std::uint64_t key) { return key < threshold; });
    }
    std::sort(first, last);
    const std::size_t end = static_cast<std::size_t>(last - seeds.begin());
    for (; next < end; ++next) {
      const int seed = static_cast<int>(seeds[next] & 0xffffffffu);
      if (ws.mark[seed] != kTaken) grow_from(seed);  // else already in R or R'
    }
  }
  // regrow_left_out: the grids of R' that fit none of the planes around them (3 x 3 grids; the
  // planes as grown, fixed during the pass) seed and grow again, in seed order; every other grid
  // is taken now, so they grow among themselves only. The rest stay out (the grid-level
  // refinement may give them to the plane they fit). The planes are fitted as needed, into the
  // refinement's ws.fits (which refits every plane).
  if (grid_.grid_level && !ws.left_out.empty()) {
    second_growth = true;
    ws.fits.resize(ws.regions.size());
    ws.region_fitted.assign(ws.regions.size(), 0);
    seeds.clear();
    for (const int c : ws.left_out) {
      const auto [cx, cy] = grid_xy(c);
      bool fits_a_plane = false;
      for (int i = 0; i < 9 && !fits_a_plane; ++i) {
        const int r = region_at(cx + i % 3 - 1, cy + i / 3 - 1);
        if (r < 0) continue;
        if (!ws.region_fitted[r]) {
          ws.fits[r] = FitSums(ws.regions[r]);
          ws.region_fitted[r] = 1;
        }
        fits_a_plane = grid_fit_ratio(ws.sums[c], ws.fits[r]) < 1.0;
      }
      if (fits_a_plane) continue;
      ws.mark[c] = -1;
      seeds.push_back(ws.seed_keys[c]);
    }
    std::sort(seeds.begin(), seeds.end());
    for (const std::uint64_t key : seeds) {
      const int seed = static_cast<int>(key & 0xffffffffu);
      if (ws.mark[seed] != kTaken) grow_from(seed);
    }
  }

  // ---- 4. Boundary refinement: edge grids, whole grids (refine_grids), then pixel labels and
  // the pixels of the edge grids (refine_boundary).
  const auto t3 = Clock::now();
  // Edge grids: a grid with a plane among its 8 neighbours that is not itself an interior grid of
  // a plane (all 8 neighbours in its own plane). Only they can hold a pixel whose plane differs
  // from a 4-neighbour's, so the refinement, the merge's adjacency and the crease pixels of the
  // ray fit look at them only.
  auto is_edge_at_border = [&](int cx, int cy) {  // with bounds checks
    const std::int32_t own = region_at(cx, cy);
    bool interior = own >= 0, any_plane = own >= 0;
    for (int oy = -1; oy <= 1; ++oy) {
      for (int ox = -1; ox <= 1; ++ox) {
        const std::int32_t r = region_at(cx + ox, cy + oy);
        if (r != own) interior = false;
        if (r >= 0) any_plane = true;
      }
    }
    return any_plane && !interior;
  };
  // In ascending grid order. Away from the image border, each row's flags come from a loop without
  // branches or bounds checks, which the compiler vectorises, and are then appended without
  // branches (a data-dependent branch per grid cost 0.3 ms a pass with 3x3 grids on TUM frames).
  auto find_edge_grids = [&] {
    ws.edge_scratch.resize(num_cells);
    ws.edge_flags.resize(cells_x);
    int* const out = ws.edge_scratch.data();
    std::uint8_t* const flags = ws.edge_flags.data();
    std::size_t n = 0;
    for (int cy = 0; cy < cells_y; ++cy) {
      const int row = cy * cells_x;
      const std::int32_t* count = ws.counts.data() + row;
      if (cy == 0 || cy + 1 == cells_y || cells_x < 3) {
        for (int cx = 0; cx < cells_x; ++cx) {
          if (count[cx] != 0 && is_edge_at_border(cx, cy)) out[n++] = row + cx;
        }
        continue;
      }
      const std::int32_t* mid = ws.cell_region.data() + row;
      const std::int32_t* up = mid - cells_x;
      const std::int32_t* down = mid + cells_x;
      if (count[0] != 0 && is_edge_at_border(0, cy)) out[n++] = row;
      const int last = cells_x - 1;  // a local: the flag stores (bytes) may alias a captured one
      for (int cx = 1; cx < last; ++cx) {
        const std::int32_t own = mid[cx];
        const std::int32_t u0 = up[cx - 1], u1 = up[cx], u2 = up[cx + 1], m0 = mid[cx - 1],
                           m2 = mid[cx + 1], d0 = down[cx - 1], d1 = down[cx], d2 = down[cx + 1];
        const bool same = (u0 == own) & (u1 == own) & (u2 == own) & (m0 == own) & (m2 == own) &
                          (d0 == own) & (d1 == own) & (d2 == own);
        const std::int32_t highest =
            std::max(std::max(std::max(std::max(own, u0), std::max(u1, u2)),
                              std::max(std::max(m0, m2), std::max(d0, d1))),
                     d2);
        flags[cx] = (count[cx] != 0) & (highest >= 0) & !((own >= 0) & same);
      }
      for (int cx = 1; cx < last; ++cx) {
        out[n] = row + cx;
        n += flags[cx];
      }
      if (count[cells_x - 1] != 0 && is_edge_at_border(cells_x - 1, cy))
        out[n++] = row + cells_x - 1;
    }
    ws.edge_grids.assign(out, out + n);
  };
  find_edge_grids();
  const std::size_t num_regions = ws.regions.size();
  // Grid-level refinement (refine_grids): each edge grid goes whole to the adjacent plane (of its
  // 8 neighbours) that fits it best within tolerance, measured as the grid's MSE about the plane
  // in units of refine_sigmas^2 times its expected MSE along the normal (depth model) or gamma^2
  // (constant model); a grid of a plane only when that fits it better than its own. This undoes
  // grids that joined a plane only because they lie within its noise: far from the sensor a
  // grid's normal is noise and gets no angle test, so a plane grazing a wall picks up the wall's
  // grids along their corner (the synthetic room's right wall with 5x5 grids: 8 % of its points,
  // 2.5 cm of offset). And it gives a plane the grids along its rim that growth left out (classed
  // non-planar, refused by a test against a young region's plane, or left in a region too small
  // to be a plane) when they fit it (grid-fast on TUM frame 0: 83.6 -> 92.7 % of the valid
  // pixels assigned); a grid that straddles two surfaces fits neither within tolerance and stays
  // out. Candidate planes are those grown in step 3, fixed during the pass, and the moves are
  // applied after it, so the result does not depend on grid order.
  // A plane whose interior grids (all 8 neighbours in it) hold under a quarter of its points: too
  // narrow for a fit to them (see the fits of the grid-level pipeline below), and refined again
  // by grid.narrow_passes.
  auto too_narrow_for_interior_fit = [](double interior_points, double all_points) {
    return interior_points < 0.25 * all_points;
  };
  // Which planes' fits in ws.fits are out of date (they gained or lost grids since).
  ws.fit_stale.assign(num_regions, 1);
  ws.fits.resize(num_regions);
  auto refit_stale = [&] {
    for (std::size_t i = 0; i < num_regions; ++i) {
      if (!ws.fit_stale[i]) continue;
      ws.fits[i] = FitSums(ws.regions[i]);
      ws.fit_stale[i] = 0;
    }
  };
  // narrow_only (a pass of grid.narrow_passes): only the grids at a narrow plane
  // (ws.at_narrow_plane), and only moves into or out of one (ws.is_narrow).
  auto refine_edge_grids = [&](bool narrow_only) {
    refit_stale();
    ws.grid_moves.clear();
    // Each plane once among a grid's candidates, without a data-dependent branch: a plane is new
    // to edge grid e while its stamp is not e + 1 (stamp 0 stands for no plane, never new).
    ws.candidate_stamp.assign(num_regions + 1, 0);
    std::int32_t* const stamp = ws.candidate_stamp.data() + 1;
    const std::size_t num_edge = ws.edge_grids.size();
    for (std::size_t e = 0; e < num_edge; ++e) {
      const int c = ws.edge_grids[e];
      if (e + kRefinePrefetchAhead < num_edge) {
        const char* ahead =
            reinterpret_cast<const char*>(&ws.sums[ws.edge_grids[e + kRefinePrefetchAhead]]);
        __builtin_prefetch(ahead);
        __builtin_prefetch(ahead + 64);
        __builtin_prefetch(ahead + sizeof(MomentSums) - 1);
      }
      const MomentSums& g = ws.sums[c];
      const auto [cx, cy] = grid_xy(c);
      const int own = ws.cell_region[c];
      if (narrow_only && !ws.at_narrow_plane[c]) continue;
      if (own < 0 && ws.counts[c] < mu_of(cx, cy)) continue;  // too few points to tell a fit
      // The planes of the 3 x 3 grids around, each once (bounds checks only at the image border).
      std::int32_t around[9];
      if (cx > 0 && cy > 0 && cx + 1 < cells_x && cy + 1 < cells_y) {
        for (int i = 0; i < 9; ++i)
          around[i] = ws.cell_region[c + (i / 3 - 1) * cells_x + i % 3 - 1];
      } else {
        for (int i = 0; i < 9; ++i) around[i] = region_at(cx + i % 3 - 1, cy + i / 3 - 1);
      }
      // A grid of a plane with only its own plane around (and no plane) stays: most edge grids.
      // Told before the stamps below, whose store and load per neighbour wait on each other when
      // the neighbours share a plane.
      bool own_plane_only = own >= 0;
      for (const std::int32_t r : around) own_plane_only &= (r == own) | (r < 0);
      if (own_plane_only) continue;
      const std::int32_t fresh_stamp = static_cast<std::int32_t>(e + 1);
      stamp[-1] = fresh_stamp;
      int candidates[9];
      int num_candidates = 0;
      for (const std::int32_t r : around) {
        candidates[num_candidates] = r;
        num_candidates += stamp[r] != fresh_stamp;
        stamp[r] = fresh_stamp;
      }
      int best = -1;
      double best_ratio = 1.0;  // beyond tolerance: no plane
      for (int i = 0; i < num_candidates; ++i) {
        const int r = candidates[i];
        const double ratio = grid_fit_ratio(g, ws.fits[r]);
        // The lower region index wins a tie, whatever the visiting order.
        if (ratio < best_ratio || (ratio == best_ratio && best >= 0 && r < best)) {
          best_ratio = ratio;
          best = r;
        }
      }
      if (best < 0 || best == own) continue;
      if (narrow_only && !ws.is_narrow[best] && !(own >= 0 && ws.is_narrow[own])) continue;
      ws.grid_moves.emplace_back(c, best);
    }
    for (const auto& [c, to] : ws.grid_moves) {
      if (ws.cell_region[c] >= 0) {
        ws.regions[ws.cell_region[c]].Subtract(ws.sums[c]);
        ws.fit_stale[ws.cell_region[c]] = 1;
      }
      ws.regions[to].Merge(ws.sums[c]);
      ws.fit_stale[to] = 1;
      ws.cell_region[c] = to;
    }
    return !ws.grid_moves.empty();
  };
  if (grid_.grid_level && num_regions > 0 && refine_edge_grids(false)) {
    find_edge_grids();
    // narrow_passes: the refinement again, around the narrow planes only, while grids move.
    for (int pass = 0; pass < (grid_.grid_level ? kNarrowPasses : 0); ++pass) {
      ws.edge_points.assign(num_regions, 0.0);
      for (const int c : ws.edge_grids) {
        const int r = ws.cell_region[c];
        if (r >= 0) ws.edge_points[r] += ws.sums[c].k;
      }
      ws.is_narrow.assign(num_regions, 0);
      bool any_narrow = false;
      for (std::size_t r = 0; r < num_regions; ++r) {
        const double all = ws.regions[r].k;
        ws.is_narrow[r] = too_narrow_for_interior_fit(all - ws.edge_points[r], all);
        any_narrow |= ws.is_narrow[r] != 0;
      }
      if (!any_narrow) break;
      // The grids at a narrow plane: its grids and their 8 neighbours.
      ws.at_narrow_plane.assign(num_cells, 0);
      for (int c = 0; c < num_cells; ++c) {
        const int r = ws.cell_region[c];
        if (r < 0 || !ws.is_narrow[r]) continue;
        const auto [cx, cy] = grid_xy(c);
        for (int oy = std::max(0, cy - 1); oy <= std::min(cells_y - 1, cy + 1); ++oy) {
          for (int ox = std::max(0, cx - 1); ox <= std::min(cells_x - 1, cx + 1); ++ox) {
            ws.at_narrow_plane[oy * cells_x + ox] = 1;
          }
        }
      }
      if (!refine_edge_grids(true)) break;
      find_edge_grids();
    }
  }
  // Pixel labels from a value per grid. Each band of k rows is written once: a row of grid values
  // expanded to pixels, appended once for every row of the band; then the invalid pixels of the
  // grids with a value >= 0 are set to -1 (listed in step 1: few of them have a value). Appended,
  // not resized and overwritten: resizing fills the whole image with zeros first, a second pass
  // over 1.2 MB (grid-fast's finalize stage 0.51 -> 0.39 ms in alternating runs on TUM frames). The
  // row is filled with the grid size known at compile time where it is 3 or 6 (GBRG's 3x3 and 6x6
  // variants).
  auto expand_to_pixels = [&](const std::int32_t* grid_values, std::vector<std::int32_t>& pixels) {
    pixels.clear();
    pixels.reserve(static_cast<std::size_t>(width) * height);
    ws.row_labels.resize(width);
    std::int32_t* const row_labels = ws.row_labels.data();
    const int whole = width / k;  // grids of k columns; one narrower may follow
    auto fill_whole_grids = [&](const std::int32_t* values, auto grid_size) {
      constexpr int kSize = decltype(grid_size)::value;
      for (int cx = 0; cx < whole; ++cx) {
        for (int j = 0; j < kSize; ++j) row_labels[cx * kSize + j] = values[cx];
      }
    };
    for (int cy = 0; cy < cells_y; ++cy) {
      const int y0 = cy * k, y1 = std::min(height, y0 + k);
      const std::int32_t* values = grid_values + static_cast<std::size_t>(cy) * cells_x;
      if (k == 3) {
        fill_whole_grids(values, std::integral_constant<int, 3>());
      } else if (k == 6) {
        fill_whole_grids(values, std::integral_constant<int, 6>());
      } else {
        for (int cx = 0; cx < whole; ++cx) std::fill_n(row_labels + cx * k, k, values[cx]);
      }
      if (whole < cells_x) std::fill(row_labels + whole * k, row_labels + width, values[whole]);
      for (int y = y0; y < y1; ++y) {
        pixels.insert(pixels.end(), ws.row_labels.begin(), ws.row_labels.end());
      }
    }
    for (const int c : ws.partly_valid) {
      if (grid_values[c] < 0) continue;
      const auto [cx, cy] = grid_xy(c);
      const int x0 = cx * k, x1 = std::min(width, x0 + k);
      const int y0 = cy * k, y1 = std::min(height, y0 + k);
      for (int y = y0; y < y1; ++y) {
        const std::size_t row = static_cast<std::size_t>(y) * width;
        for (int x = x0; x < x1; ++x) {
          if (!std::isfinite(pts[row + x].z())) pixels[row + x] = -1;
        }
      }
    }
  };
  // Without the pixel-level refinement every valid pixel keeps its grid's label (the ray fit then
  // moves no pixel at a crease either): region borders, merging and plane ids are worked out on
  // the grid image (k^2 times fewer labels), and the pixel labels written once, from the plane
  // ids, at the end.
  const bool grid_labels = !params_.refine_boundary;
  ws.pixel_overrides.clear();
  if (!grid_labels) expand_to_pixels(ws.cell_region.data(), ws.labels);
  // Region ray sums from their grids' (the refinement below corrects them pixel by pixel).
  ws.rays.assign(params_.ray_fit ? num_regions : 0, RaySums());
  if (params_.ray_fit) {
    // The grids' ray sums (2.4 MB for 3x3 grids) left the cache since the moments pass: fetched
    // 1 kB ahead, which the hardware prefetcher alone did not keep up with (0.29 -> 0.23 ms).
    for (int c = 0; c < num_cells; ++c) {
      __builtin_prefetch(reinterpret_cast<const char*>(ws.grid_rays.data() + c) + 1024);
      if (ws.cell_region[c] >= 0) ws.rays[ws.cell_region[c]].Add(ws.grid_rays[c]);
    }
  }
  // The pixel-level refinement's choice for one pixel (refine_boundary, and the narrow planes
  // below): of the candidate planes (n, d: four floats each), the nearest in units of the pixel's
  // tolerance, refine_sigmas sigma_n with sigma_n = sigma(z) |n.p| / z (gamma under the constant
  // model), if within it, else -1; an earlier candidate wins a tie. Compared as
  // best_dist * tol < dist * best_tol (no division), from ratio 1 (beyond tolerance). In float:
  // at 50 m its rounding is a few micrometres, against tolerances of millimetres or more.
  const float refine_sigmas_f = static_cast<float>(params_.refine_sigmas);
  const float sigma_z2_f = static_cast<float>(s2), gamma_f = static_cast<float>(params_.gamma);
  auto relative_noise = [&](float z) {  // sigma(z) / z
    return s0 == 0.0 ? sigma_z2_f * z : static_cast<float>(params_.Sigma(z) / z);
  };
  // A plane in best_plane_for_pixel's form: the eigen fit of `m` as n, d in float, appended.
  auto append_plane_nd = [](const MomentSums& m, std::vector<float>& planes) {
    const FastFit f = FitSums(m);
    planes.insert(planes.end(), {static_cast<float>(f.normal.x()), static_cast<float>(f.normal.y()),
                                 static_cast<float>(f.normal.z()), static_cast<float>(f.d)});
  };
  // A pixel's distance to one candidate plane (n, d) and its tolerance there.
  auto distance_and_tolerance = [&](const Eigen::Vector3f& pf, float rel, const float* plane,
                                    float& dist, float& tol) {
    const float np = plane[0] * pf.x() + plane[1] * pf.y() + plane[2] * pf.z();
    tol = depth_model ? refine_sigmas_f * rel * std::abs(np) : gamma_f;
    dist = std::abs(np - plane[3]);
  };
  auto best_plane_for_pixel = [&](const Eigen::Vector3f& pf, float rel, const float* planes,
                                  int n) {
    int best = -1;
    float best_dist = 1.0f, best_tol = 1.0f;
    for (int i = 0; i < n; ++i) {
      float dist, tol;
      distance_and_tolerance(pf, rel, planes + 4 * i, dist, tol);
      // Selects rather than branches: which candidate wins is data, not a pattern.
      const bool better = dist * best_tol < best_dist * tol;
      best_dist = better ? dist : best_dist;
      best_tol = better ? tol : best_tol;
      best = better ? i : best;
    }
    return best;
  };
  if (params_.refine_boundary && num_regions > 0) {
    // Pixel-level refinement of every edge grid: each valid pixel goes to the best-fitting
    // candidate plane (its own and the 8 neighbours') when within its tolerance, else to none.
    // Interior grids keep all their pixels. Candidate planes are the ones grown in step 3 (fixed
    // during the pass, so the result does not depend on grid order). "Best" is the smallest
    // distance in units of the pixel's tolerance. Under the depth model the tolerance is noise
    // only, refine_sigmas sigma_n with sigma_n = sigma(z) |n.p| / z (plane-dependent): the base
    // gamma, which lets growth absorb a large region's gentle bending, would here hand a plane
    // the strip of the adjacent surface along their crease and the mixed pixels of depth edges,
    // which tilt its fit (TUM fr3 k = 1 repeatability, grid4: median angle 0.251 -> 0.236 deg).
    // Each plane's n, d in float, once, not per edge grid.
    ws.plane_nd.clear();
    for (std::size_t i = 0; i < num_regions; ++i) append_plane_nd(ws.regions[i], ws.plane_nd);
    // The moved pixels of one edge grid, in pixel order: (pixel, slot of the candidate plane it
    // goes to, n_adj: none).
    ws.moved_pixels.resize(static_cast<std::size_t>(k) * k);
    std::pair<std::size_t, int>* const moved = ws.moved_pixels.data();
    float cand[9][4];       // the candidate planes of a grid: n, d
    MomentSums gained[10];  // per candidate plane of the grid (and none): what it gains
    RaySums gained_rays[10];
    const std::size_t num_edge = ws.edge_grids.size();
    for (std::size_t e = 0; e < num_edge; ++e) {
      const int c = ws.edge_grids[e];
      // The points of an edge grid were last read by the moments pass and have left the core's
      // caches since; the edge grids come with gaps the hardware prefetcher does not follow.
      // Fetch the rows of the grid a few places ahead (first and last point of each row, and
      // its labels, for writing: refinement step on TUM frames 1.90 -> 1.79 ms).
      if (e + kRefinePrefetchAhead < num_edge) {
        const int ahead = ws.edge_grids[e + kRefinePrefetchAhead];
        const auto [ax, ay] = grid_xy(ahead);
        const int ay1 = std::min(height, ay * k + k), ax1 = std::min(width, ax * k + k) - 1;
        for (int y = ay * k; y < ay1; ++y) {
          const std::size_t row = static_cast<std::size_t>(y) * width;
          __builtin_prefetch(pts + row + ax * k);
          __builtin_prefetch(pts + row + ax1);
          __builtin_prefetch(ws.labels.data() + row + ax * k, 1);  // written below
        }
        // Its noise weight too, read when pixels leave: in an array of 34k grids (3x3) that
        // leaves the cache as well (the step 1.87 -> 1.52 and 1.82 -> 1.67 ms).
        __builtin_prefetch(&ws.noise_weight[ahead]);
      }
      const auto [cx, cy] = grid_xy(c);
      const int own = ws.cell_region[c];
      // The planes of the grid and its 8 neighbours (-1: none or outside the image), read without
      // bounds checks away from the image border.
      int around[9];
      if (cx > 0 && cy > 0 && cx + 1 < cells_x && cy + 1 < cells_y) {
        const std::int32_t* above = ws.cell_region.data() + (c - cells_x - 1);
        for (int i = 0; i < 3; ++i) {
          around[i] = above[i];
          around[3 + i] = above[cells_x + i];
          around[6 + i] = above[2 * cells_x + i];
        }
      } else {
        for (int i = 0; i < 9; ++i) around[i] = region_at(cx + i % 3 - 1, cy + i / 3 - 1);
      }
      int adj[9];
      int n_adj = 0;
      for (const int r : around) {
        if (r < 0) continue;
        // Insert keeping adj sorted and unique: the lowest region index wins distance ties.
        int pos = 0;
        while (pos < n_adj && adj[pos] < r) ++pos;
        if (pos < n_adj && adj[pos] == r) continue;
        for (int j = n_adj; j > pos; --j) adj[j] = adj[j - 1];
        adj[pos] = r;
        ++n_adj;
      }
      for (int i = 0; i < n_adj; ++i) {
        std::memcpy(cand[i], ws.plane_nd.data() + 4 * adj[i], sizeof(cand[i]));
      }
      // Each valid pixel's plane, and whether they all went to one.
      const int y0 = cy * k, x0 = cx * k;
      const int y1 = std::min(height, y0 + k), x1 = std::min(width, x0 + k);
      int first_to = -2;  // -2: no valid pixel yet
      bool one_plane = true;
      std::size_t num_moved = 0;  // valid pixels that leave `own`, with their slot (below)
      // One copy of the pixel loop for a grid with a single candidate plane (most edge grids: a
      // plane beside no other), where best_plane_for_pixel reduces to distance < tolerance (its
      // comparison multiplies each side by 1: the same result).
      auto label_pixels = [&](auto single_candidate) {
        for (int y = y0; y < y1; ++y) {
          for (int x = x0; x < x1; ++x) {
            const std::size_t idx = static_cast<std::size_t>(y) * width + x;
            const Eigen::Vector3f& pf = pts[idx];
            if (!std::isfinite(pf.z())) continue;
            const float z = internal::PointDepth(pf, spherical);
            int best;
            if constexpr (decltype(single_candidate)::value) {
              float dist, tol;
              distance_and_tolerance(pf, relative_noise(z), cand[0], dist, tol);
              best = dist < tol ? 0 : -1;
            } else {
              best = best_plane_for_pixel(pf, relative_noise(z), &cand[0][0], n_adj);
            }
            const int to = best >= 0 ? adj[best] : -1;
            ws.labels[idx] = to;
            moved[num_moved] = {idx, best >= 0 ? best : n_adj};  // kept if it leaves (no branch)
            num_moved += to != own;
            if (first_to == -2) first_to = to;
            one_plane &= to == first_to;
          }
        }
      };
      if (n_adj == 1) {
        label_pixels(std::true_type());
      } else {
        label_pixels(std::false_type());
      }
      if (num_moved == 0) continue;
      if (one_plane) {
        // The whole grid changes plane: move its sums.
        if (own >= 0) {
          ws.regions[own].Subtract(ws.sums[c]);
          if (params_.ray_fit) ws.rays[own].Subtract(ws.grid_rays[c]);
        }
        if (first_to >= 0) {
          ws.regions[first_to].Merge(ws.sums[c]);
          if (params_.ray_fit) ws.rays[first_to].Add(ws.grid_rays[c]);
        }
        continue;
      }
      // Else only the pixels that change plane change the sums: each moved pixel is added to
      // the slot of where it goes (slot n_adj: to no plane); what the grid's own plane loses is
      // all the slots together. Applied once per grid; the noise moment takes the grid's
      // weight, as the grid's own sums do.
      for (int i = 0; i <= n_adj; ++i) {
        gained[i] = MomentSums();
        gained_rays[i] = RaySums();
      }
      for (std::size_t i = 0; i < num_moved; ++i) {
        const auto [idx, slot] = moved[i];
        const Eigen::Vector3f& pf = pts[idx];
        gained[slot].AddPosition(pf.x(), pf.y(), pf.z());
        const float z = internal::PointDepth(pf, spherical);
        if (params_.ray_fit && z > 0.0f) gained_rays[slot].Add(pf, z, params_.RayFitWeight(z));
      }
      const double w = ws.noise_weight[c];
      MomentSums lost;
      RaySums lost_rays;
      for (int i = 0; i <= n_adj; ++i) {
        if (gained[i].k == 0) continue;
        gained[i].SetUniformNoise(w);
        lost.Merge(gained[i]);
        lost_rays.Add(gained_rays[i]);
        if (i == n_adj) continue;  // the pixels that leave every plane
        ws.regions[adj[i]].Merge(gained[i]);
        if (params_.ray_fit) ws.rays[adj[i]].Add(gained_rays[i]);
      }
      if (own >= 0) {
        ws.regions[own].Subtract(lost);
        if (params_.ray_fit) ws.rays[own].Subtract(lost_rays);
      }
    }
  }

  // ---- 5. Merge adjacent regions that are one surface; final planes from all their pixels.
  const auto t4 = Clock::now();
  std::vector<std::int32_t>& region_image = grid_labels ? ws.cell_region : ws.labels;
  internal::RegionBorders borders;
  if (params_.merge_regions || (params_.ray_fit && !grid_labels)) {
    internal::RegionBorderScan scan(region_image, grid_labels ? cells_x : width,
                                    grid_labels ? cells_y : height);
    const std::size_t num_edge = ws.edge_grids.size();
    for (std::size_t e = 0; e < num_edge; ++e) {
      const int c = ws.edge_grids[e];
      const auto [cx, cy] = grid_xy(c);
      if (grid_labels) {
        scan.Scan(cx, cy, cx + 1, cy + 1);
      } else {
        // The label image (1.2 MB) has left the core's caches since the refinement wrote it:
        // fetch the rows the scan of a grid a few places ahead reads (its k rows and the rows
        // above and below; the scan on TUM frames 0.80 -> 0.67 ms).
        if (e + kRefinePrefetchAhead < num_edge) {
          const auto [ax, ay] = grid_xy(ws.edge_grids[e + kRefinePrefetchAhead]);
          const int ry0 = std::max(0, ay * k - 1), ry1 = std::min(height, ay * k + k + 1);
          for (int y = ry0; y < ry1; ++y) {
            __builtin_prefetch(region_image.data() + static_cast<std::size_t>(y) * width + ax * k);
          }
        }
        scan.Scan(cx * k, cy * k, std::min(width, (cx + 1) * k), std::min(height, (cy + 1) * k));
      }
    }
    borders = scan.Finish();
  }
  ws.label_root.clear();
  if (params_.merge_regions) {
    // A pixel image's relabelling waits for the plane ids (one pass for both); a grid image, which
    // the narrow planes below read, is relabelled now.
    internal::MergeCoplanarRegions(region_image, borders.pairs, ws.regions, ws.rays, params_,
                                   grid_labels ? nullptr : &ws.label_root);
  }
  // A plane too narrow for its grids apart from the other planes as well (a column of grids or
  // two, each next to another plane) holds another surface's pixels in most of its grids: fitted
  // to all of them, the synthetic room's right wall turned to 22-23.5 deg (6-9 px wide at 3.8 m,
  // 2300-3500 px) came out 2.6 cm to 0.9 m off noise-free with 6x6 grids, and was labelled with
  // grids holding as much of the back wall as of it. Its grids and the grids around them get the
  // pixel-level refinement of the other methods: a pixel of its grids goes to whichever of it and
  // the planes next to its grids fits the pixel best within the pixel's tolerance, else to none;
  // a pixel of a grid around goes to it when it fits the pixel within tolerance and better than
  // the grid's own plane does. Its plane is then fitted to its pixels; labels and sums follow.
  // (A pixel it gives away to a plane that is too narrow as well goes to none.) Only planes of
  // grid.narrow_refine_points or more (see there).
  auto refine_narrow_plane = [&](int r, const std::vector<int>& grids) {
    // Its plane and the planes next to its grids, as best_plane_for_pixel's candidates.
    std::vector<int>& candidates = ws.candidates;
    std::vector<int>& candidate_grid = ws.candidate_grid;  // a grid of each, for its plane id
    std::vector<float>& planes = ws.candidate_planes;
    candidates.clear();
    candidate_grid.clear();
    planes.clear();
    auto add_candidate = [&](int region, int grid, const MomentSums& m) {
      candidates.push_back(region);
      candidate_grid.push_back(grid);
      append_plane_nd(m, planes);
    };
    add_candidate(r, grids.front(), ws.regions[r]);
    // One walk over the 3 x 3 neighbourhoods of its grids: the planes there (candidates) and the
    // grids around its grids (each once; not those of a plane too narrow as well).
    std::vector<int>& around = ws.narrow_around;
    around.clear();
    for (const int c : grids) {
      const auto [cx, cy] = grid_xy(c);
      for (int i = 0; i < 9; ++i) {
        const int ox = cx + i % 3 - 1, oy = cy + i / 3 - 1;
        if (ox < 0 || oy < 0 || ox >= cells_x || oy >= cells_y) continue;
        const int n = oy * cells_x + ox;
        const int o = ws.cell_region[n];
        if (o == r) continue;
        if (o >= 0 && std::find(candidates.begin(), candidates.end(), o) == candidates.end()) {
          const MomentSums& m = ws.fit_sums[o].k >= 3 ? ws.fit_sums[o] : ws.regions[o];
          if (m.k >= 3) add_candidate(o, n, m);
        }
        if ((o >= 0 && ws.too_narrow[o]) || ws.counts[n] == 0 || ws.visit[n] == r) continue;
        ws.visit[n] = r;
        around.push_back(n);
      }
    }
    auto for_each_pixel = [&](int c, const auto& visit_pixel) {
      const auto [cx, cy] = grid_xy(c);
      const int x0 = cx * k, y0 = cy * k;
      const int x1 = std::min(width, x0 + k), y1 = std::min(height, y0 + k);
      for (int y = y0; y < y1; ++y) {
        for (int x = x0; x < x1; ++x) {
          const std::size_t i = static_cast<std::size_t>(y) * width + x;
          const Eigen::Vector3f& pf = pts[i];
          if (std::isfinite(pf.z())) visit_pixel(i, pf);
        }
      }
    };
    // Its grids' pixels: to the best candidate (0: itself), else to none. The pixels of the
    // grids around its grids: to it when it is the better of it and the grid's own plane, within
    // tolerance. Each pixel's choice: (pixel, its grid, candidate: 0 itself, -1 none; for a pixel
    // of a grid around that stays, the grid's own plane's candidate, or -2 when that is none).
    auto& choices = ws.narrow_choices;
    choices.clear();
    const int num_candidates = static_cast<int>(candidates.size());
    for (const int c : grids) {
      for_each_pixel(c, [&](std::size_t i, const Eigen::Vector3f& pf) {
        const float z = internal::PointDepth(pf, spherical);
        choices.push_back(
            {i, c, best_plane_for_pixel(pf, relative_noise(z), planes.data(), num_candidates)});
      });
    }
    const std::size_t num_own_grid_pixels = choices.size();
    for (const int n : around) {
      const int o = ws.cell_region[n];
      const int j =
          static_cast<int>(std::find(candidates.begin(), candidates.end(), o) - candidates.begin());
      float pair[8];  // itself, then the grid's own plane if it is a candidate
      std::copy(planes.begin(), planes.begin() + 4, pair);
      const int num_pair = j < num_candidates ? 2 : 1;
      if (num_pair == 2) std::copy(planes.begin() + 4 * j, planes.begin() + 4 * j + 4, pair + 4);
      const int stays = num_pair == 2 ? j : o < 0 ? -1 : -2;
      for_each_pixel(n, [&](std::size_t i, const Eigen::Vector3f& pf) {
        const float z = internal::PointDepth(pf, spherical);
        const bool joins = best_plane_for_pixel(pf, relative_noise(z), pair, num_pair) == 0;
        choices.push_back({i, n, joins ? 0 : stays});
      });
    }
    // The candidates above are eigen fits, and its own, of grids that hold other surfaces too, is
    // tilted (on a surface seen at a grazing angle, by the depth noise as well: see ray_fit), so
    // the pixels chosen against it are too. With the ray fit the choice is made a second time
    // against the planes along the rays (its own of the pixels chosen first, the others' of
    // their fit subsets), as the final crease competition of the pixel-level methods makes it: a
    // pixel moves to a candidate whose surface its ray sees (VisibleHere), and a pixel of no
    // plane joins the candidate that passes nearest it along the ray, within the gate. (Synthetic
    // room, Kinect noise, the right wall turned 23 deg, 638 px wide, grid3-fast: a column of its
    // pixels along the crease went to the back wall, and it came out 4.4 cm off.)
    if (params_.ray_fit) {
      // Its own plane along the rays is fitted to the blocks of 2 x 2 pixels of its grids that
      // fit it better than any other candidate, within tolerance (summed squared distances in
      // units of each pixel's tolerance), rather than to the pixels chosen first: its eigen fit
      // is tilted towards the neighbour its whole grids hold too, the pixels of the neighbour's
      // strip along the crease fit it, and a fit of them keeps the tilt (the synthetic room's
      // right wall turned 23 deg, 638 px wide, Kinect noise, grid-fast: a column of the back
      // wall, 390 px, kept on 7 of 10 noise draws, 2.0-3.0 cm off). A block averages the noise
      // of four pixels, so it tells the two surfaces apart where a pixel cannot. (Fitting the
      // plane's final pixels to the blocks as well broke renders where grid3-fast passed: 1 -> 47
      // of 2310.) With no such block, the pixels chosen first.
      MomentSums first;
      RaySums first_rays;
      auto add_to_first = [&](const Eigen::Vector3f& pf) {
        first.AddPosition(pf.x(), pf.y(), pf.z());
        const float z = internal::PointDepth(pf, spherical);
        if (z > 0.0f) first_rays.Add(pf, z, params_.RayFitWeight(z));
      };
      constexpr int kBlock = 2;
      std::vector<float>& block_ratio = ws.block_ratio;
      block_ratio.resize(num_candidates);
      for (const int c : grids) {
        const auto [cx, cy] = grid_xy(c);
        const int gx0 = cx * k, gy0 = cy * k;
        const int gx1 = std::min(width, gx0 + k), gy1 = std::min(height, gy0 + k);
        for (int by = gy0; by < gy1; by += kBlock) {
          for (int bx = gx0; bx < gx1; bx += kBlock) {
            const int bx1 = std::min(gx1, bx + kBlock), by1 = std::min(gy1, by + kBlock);
            auto for_each_block_point = [&](const auto& visit) {
              for (int y = by; y < by1; ++y) {
                for (int x = bx; x < bx1; ++x) {
                  const Eigen::Vector3f& pf = pts[static_cast<std::size_t>(y) * width + x];
                  if (std::isfinite(pf.z())) visit(pf);
                }
              }
            };
            std::fill(block_ratio.begin(), block_ratio.end(), 0.0f);
            int count = 0;
            for_each_block_point([&](const Eigen::Vector3f& pf) {
              ++count;
              const float rel = relative_noise(internal::PointDepth(pf, spherical));
              for (int j = 0; j < num_candidates; ++j) {
                float dist, tol;
                distance_and_tolerance(pf, rel, planes.data() + 4 * j, dist, tol);
                block_ratio[j] += dist * dist / std::max(tol * tol, 1e-18f);
              }
            });
            if (count == 0 || !(block_ratio[0] < count)) continue;
            const auto best = std::min_element(block_ratio.begin(), block_ratio.end());
            if (best != block_ratio.begin()) continue;  // another candidate fits it better
            for_each_block_point(add_to_first);
          }
        }
      }
      if (first.k < 3) {
        for (const auto& [i, c, to] : choices) {
          if (to == 0) add_to_first(pts[i]);
        }
      }
      auto& ray_planes = ws.candidate_ray_planes;
      ray_planes.assign(candidates.size(), internal::RayPlane());
      ray_planes[0] = internal::SolveRegion(first_rays, first);
      for (std::size_t j = 1; j < candidates.size(); ++j) {
        const int o = candidates[j];
        ray_planes[j] = ws.fit_sums[o].k >= 3
                            ? internal::SolveRegion(ws.fit_rays[o], ws.fit_sums[o])
                            : internal::SolveRegion(ws.rays[o], ws.regions[o]);
      }
      if (ray_planes[0].ok) {
        for (std::size_t e = 0; e < choices.size(); ++e) {
          auto& [i, c, to] = choices[e];
          if (to == -2) continue;  // a pixel of a plane that is no candidate
          const Eigen::Vector3f& pf = pts[i];
          const float s = internal::PointDepth(pf, spherical);
          if (!(s > 0.0f)) continue;
          const bool own_grid = e < num_own_grid_pixels;
          if (to < 0) {
            // Of no plane: to the nearest candidate along the ray within the gate (a pixel of a
            // grid around only to this plane).
            double best_offset = internal::kCreaseGateSigmas * params_.Sigma(s);
            for (int j = 0; j < (own_grid ? num_candidates : 1); ++j) {
              if (!ray_planes[j].ok) continue;
              const double offset = internal::RayOffset(pf, s, ray_planes[j]);
              if (offset < best_offset) {
                best_offset = offset;
                to = j;
              }
            }
            continue;
          }
          if (!ray_planes[to].ok) continue;
          // Of a plane: to another whose surface its ray sees (a pixel of a grid around only to
          // this plane).
          for (int j = 0; j < (own_grid ? num_candidates : 1); ++j) {
            if (j == to || !ray_planes[j].ok) continue;
            if (internal::VisibleHere(pf, s, ray_planes[to], ray_planes[j], params_)) {
              to = j;
              break;
            }
          }
        }
      }
    }
    auto& moves = ws.narrow_moves;  // (pixel, its grid, candidate it goes to: 0 itself, -1 none)
    moves.clear();
    MomentSums own;
    for (std::size_t e = 0; e < choices.size(); ++e) {
      const auto& [i, c, to] = choices[e];
      const bool own_grid = e < num_own_grid_pixels;
      if (!own_grid && to != 0) continue;  // a pixel around that stays where it was
      const Eigen::Vector3f& pf = pts[i];
      if (to == 0) own.Add(pf.x(), pf.y(), pf.z(), ws.noise_weight[c]);
      if (!own_grid || to != 0) moves.emplace_back(i, c, to);
    }
    if (own.k < 3) return;  // nothing of its own: it stays as it was
    // Apply: its sums become those of its pixels; the others' gain and lose what moved.
    RaySums own_rays;
    for (const int c : grids) {
      // Its grids' rays, less those of the pixels that leave (added below with weight -w).
      if (params_.ray_fit) own_rays.Add(ws.grid_rays[c]);
    }
    for (const auto& [i, c, to] : moves) {
      const Eigen::Vector3f& pf = pts[i];
      const float z = internal::PointDepth(pf, spherical);
      const int from = ws.cell_region[c];
      MomentSums pixel;
      pixel.Add(pf.x(), pf.y(), pf.z(), ws.noise_weight[c]);
      if (to == 0) {  // from a grid around into this plane
        if (from >= 0) ws.regions[from].Subtract(pixel);
        if (params_.ray_fit && z > 0.0f) own_rays.Add(pf, z, params_.RayFitWeight(z));
        ws.pixel_overrides.emplace_back(i, grids.front());
        continue;
      }
      // Out of this plane's grids: to another plane, or to none.
      if (params_.ray_fit && z > 0.0f) own_rays.Add(pf, z, -params_.RayFitWeight(z));
      const bool to_other = to > 0 && !ws.too_narrow[candidates[to]];
      if (to_other) ws.regions[candidates[to]].Merge(pixel);
      ws.pixel_overrides.emplace_back(i, to_other ? candidate_grid[to] : -1);
    }
    ws.regions[r] = own;
    ws.fit_sums[r] = own;
    if (params_.ray_fit) ws.fit_rays[r] = own_rays;
  };
  if (grid_labels) {
    // The planes of whole grids. With the grid-level refinement, each is fitted to its interior
    // grids (all 8 neighbours in the same plane before merging): a grid on a plane's border may
    // hold another surface too, at a crease with another plane or at the rim of something that
    // is no plane. With 5x5 grids, fitted to all its grids, the synthetic room's narrow grazing
    // right wall came out up to 16 mm off (noise-free, depending on where the corner falls in the
    // grids) and 2.6 cm with Kinect noise, and a 3200-pixel plane of the simulated room 2.6 deg
    // off. A plane too narrow for that (under a quarter of its points left) is fitted to all its
    // grids but those next to another plane (with 6x6 grids the same wall, two or three grids
    // wide, came out 6-11 mm off, noise-free, fitted with the column of grids along its corner),
    // and one too narrow for that as well keeps them all (or is refined pixel by pixel, from
    // grid.narrow_refine_points; with grid.refine_interior_fraction, so is a plane of that many
    // points with less of them interior). Without the grid-level refinement each plane is fitted
    // to all its grids (no copy).
    if (grid_.grid_level) {
      ws.fit_sums = ws.regions;
      ws.fit_rays = ws.rays;
      // Every grid of a plane that is not interior. Their sums and ray sums (200 bytes a grid,
      // in arrays of 6.8 MB with 3x3 grids) have left the caches since the moments pass: fetched
      // a few edge grids ahead.
      const std::size_t num_edge = ws.edge_grids.size();
      for (std::size_t e = 0; e < num_edge; ++e) {
        if (e + kRefinePrefetchAhead < num_edge) {
          const int ahead = ws.edge_grids[e + kRefinePrefetchAhead];
          const char* sums = reinterpret_cast<const char*>(&ws.sums[ahead]);
          __builtin_prefetch(sums);
          __builtin_prefetch(sums + 64);
          __builtin_prefetch(sums + sizeof(MomentSums) - 1);
          if (params_.ray_fit) {
            const char* rays = reinterpret_cast<const char*>(&ws.grid_rays[ahead]);
            __builtin_prefetch(rays);
            __builtin_prefetch(rays + sizeof(RaySums) - 1);
          }
        }
        const int c = ws.edge_grids[e];
        const int r = ws.cell_region[c];
        if (r < 0) continue;
        ws.fit_sums[r].Subtract(ws.sums[c]);
        if (params_.ray_fit) ws.fit_rays[r].Subtract(ws.grid_rays[c]);
      }
      // The narrow planes only (most frames have none): their grids next to another plane.
      ws.narrow.assign(num_regions, 0);
      bool any_narrow = false;
      for (std::size_t r = 0; r < num_regions; ++r) {
        // 1: too narrow for its interior grids; 2: refined pixel by pixel whatever its grids
        // apart from the other planes hold (refine_interior_fraction).
        const double interior = ws.fit_sums[r].k, all = ws.regions[r].k;
        ws.narrow[r] = too_narrow_for_interior_fit(interior, all) ? 1 : 0;
        any_narrow |= ws.narrow[r] != 0;
      }
      if (any_narrow) {
        for (std::size_t r = 0; r < num_regions; ++r) {
          if (!ws.narrow[r]) continue;
          ws.fit_sums[r] = ws.regions[r];
          if (params_.ray_fit) ws.fit_rays[r] = ws.rays[r];
        }
        ws.apart_sums = ws.fit_sums;
        ws.apart_rays = ws.fit_rays;
        for (const int c : ws.edge_grids) {
          const int r = ws.cell_region[c];
          if (r < 0 || !ws.narrow[r]) continue;
          const auto [cx, cy] = grid_xy(c);
          bool next_to_other_plane = false;
          for (int i = 0; i < 9; ++i) {
            const int o = region_at(cx + i % 3 - 1, cy + i / 3 - 1);
            next_to_other_plane |= o >= 0 && o != r;
          }
          if (!next_to_other_plane) continue;
          ws.apart_sums[r].Subtract(ws.sums[c]);
          if (params_.ray_fit) ws.apart_rays[r].Subtract(ws.grid_rays[c]);
        }
        ws.too_narrow.assign(num_regions, 0);
        ws.refine_pixels.assign(num_regions, 0);
        bool any_refined = false;
        for (std::size_t r = 0; r < num_regions; ++r) {
          if (!ws.narrow[r]) continue;
          if (ws.narrow[r] == 1 && ws.apart_sums[r].k >= 0.25 * ws.regions[r].k) {
            ws.fit_sums[r] = ws.apart_sums[r];
            if (params_.ray_fit) ws.fit_rays[r] = ws.apart_rays[r];
          } else {
            ws.too_narrow[r] = 1;
            ws.refine_pixels[r] = ws.regions[r].k >= kNarrowRefinePoints;
            any_refined |= ws.refine_pixels[r] != 0;
          }
        }
        if (any_refined) {
          // Their grids, plane by plane (then in grid order), from one look at every grid.
          ws.narrow_plane_grids.clear();
          for (int c = 0; c < num_cells; ++c) {
            const int r = ws.cell_region[c];
            if (r >= 0 && ws.refine_pixels[r]) ws.narrow_plane_grids.emplace_back(r, c);
          }
          std::sort(ws.narrow_plane_grids.begin(), ws.narrow_plane_grids.end());
          ws.visit.assign(num_cells, -1);
          for (std::size_t i = 0; i < ws.narrow_plane_grids.size();) {
            const int r = ws.narrow_plane_grids[i].first;
            ws.narrow_grids.clear();
            for (; i < ws.narrow_plane_grids.size() && ws.narrow_plane_grids[i].first == r; ++i) {
              ws.narrow_grids.push_back(ws.narrow_plane_grids[i].second);
            }
            refine_narrow_plane(r, ws.narrow_grids);
          }
        }
      }
    }
  }
  const bool interior_fit = grid_labels && grid_.grid_level;
  internal::FinalizeSegmentation(
      cloud, region_image, ws.regions, ws.rays, borders.pixels, params_, out,
      grid_labels ? (interior_fit ? &ws.fit_sums : &ws.regions) : nullptr,
      grid_labels ? (interior_fit ? &ws.fit_rays : &ws.rays) : nullptr, ws.label_root);
  if (grid_labels) {  // out.labels holds each grid's plane id: expand it to the pixels
    ws.grid_ids.swap(out.labels);
    expand_to_pixels(ws.grid_ids.data(), out.labels);
    for (const auto& [i, grid] : ws.pixel_overrides) {
      out.labels[i] = grid >= 0 ? ws.grid_ids[grid] : -1;
    }
  }
  out.cell_classes = ws.classes;
  const auto t5 = Clock::now();
  out.timings_ms = {{"moments", Ms(t0, t2) - classify_ms},
                    {"classify", classify_ms},
                    {"grow", Ms(t2, t3)},
                    {"refine", Ms(t3, t4)},
                    {"finalize", Ms(t4, t5)}};
  return out;
}

}  // namespace planeslam::detection
