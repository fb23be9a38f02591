// GBRG stage 1: per-grid moments and shape classification (Xiao et al. 2011, Section III-A).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>

#include "grid_pipeline.hpp"

namespace planeslam::detection::gbrg {
namespace {

using Clock = std::chrono::steady_clock;

/// Grids classified per batch (the batch arrays of a chunk take about 130 kB).
constexpr int kClassifyChunk = 1024;

/// Seed key: the MSE as a float's bit pattern (monotonic for non-negative floats) above the grid
/// index, so one sort of 64-bit keys gives the order a min-heap of (MSE, index) would pop.
std::uint64_t SeedKey(double mse, int c) {
  const float f = static_cast<float>(std::max(mse, 0.0));
  std::uint32_t bits;
  std::memcpy(&bits, &f, 4);
  return static_cast<std::uint64_t>(bits) << 32 | static_cast<std::uint32_t>(c);
}

/// The batch arrays of one chunk of non-sparse grids, one array per figure, so the eigenvalue,
/// eigenvector and noise kernels each run over a whole chunk (the batch keeps the divisions and
/// square roots of many grids in flight).
struct ClassifyBatch {
  std::vector<int> dense;                   ///< the non-sparse grids of the chunk
  std::vector<double> scatter[6];           ///< their scatter, one array per entry
  std::vector<double> l1, l2, l3;           ///< their eigenvalues, ascending
  std::vector<double> v1[3];                ///< their smallest eigenvectors
  std::vector<double> l1_refined;           ///< l1 as the Rayleigh quotient of v1
  std::vector<double> eigen_ok;             ///< 0: l1..l3 to come from the closed form
  std::vector<double> dense_k, dense_w[6];  ///< their K and noise moment W (GridNoiseBatch)
  std::vector<double> isotropic, tilt, effective, angle;  ///< GridNoiseBatch's figures of them

  void Resize() {
    dense.resize(kClassifyChunk);
    for (auto& column : scatter) column.resize(kClassifyChunk);
    for (auto* l :
         {&l1, &l2, &l3, &eigen_ok, &l1_refined, &dense_k, &isotropic, &tilt, &effective, &angle}) {
      l->resize(kClassifyChunk);
    }
    for (auto& column : v1) column.resize(kClassifyChunk);
    for (auto& column : dense_w) column.resize(kClassifyChunk);
  }
};

/// Shape classification (Section III-A) and the planar grids' planes and seed keys.
class Classifier {
 public:
  Classifier(const GridImage& image, CellMoments& cells, ClassifyBatch& batch, SimdKernel kernel)
      : image_(image),
        params_(image.params),
        grid_(image.grid),
        cells_(cells),
        b_(batch),
        kernel_(kernel),
        eta_(params_.eta_deg * M_PI / 180.0),
        cos_eta_(std::cos(eta_)) {}

  /// Classifies the grids in [begin, end), one row of grids.
  void ClassifyRow(int begin, int end) {
    const int cy = image_.Xy(begin).second;
    const double row_mu = image_.MuOf(0, cy), last_mu = image_.MuOf(image_.cells_x - 1, cy);
    for (int next = begin; next < end;) {
      // The non-sparse grids listed without a branch per grid (which ones are is data).
      int num_dense = 0;
      int* const dense = b_.dense.data();
      for (; next < end && num_dense < kClassifyChunk; ++next) {
        dense[num_dense] = next;
        num_dense += cells_.counts[next] >= (next + 1 == end ? last_mu : row_mu);  // else sparse
      }
      RunKernels(num_dense);
      for (int j = 0; j < num_dense; ++j) ApplyRules(j);
    }
  }

 private:
  /// The chunk's scatter, eigenvalues, eigenvectors and noise figures.
  void RunKernels(int num_dense) {
    for (int j = 0; j < num_dense; ++j) {
      const MomentSums& s = cells_.sums[b_.dense[j]];
      double scatter[6];
      s.Scatter(scatter);
      for (int i = 0; i < 6; ++i) b_.scatter[i][j] = scatter[i];
      b_.dense_k[j] = s.k;
      const double w[6] = {s.wxx, s.wxy, s.wxz, s.wyy, s.wyz, s.wzz};
      for (int i = 0; i < 6; ++i) b_.dense_w[i][j] = w[i];
    }
    // A grid's eigenvalues feed thresholds and a float seed key: Newton's last step below 1e-9 of
    // the trace is plenty (a grid whose normal is read refines l1 as its Rayleigh quotient
    // anyway). Lanes where it is not reached in eight steps (l1 close to l2) use the closed form.
    const double* columns[6];
    for (int i = 0; i < 6; ++i) columns[i] = b_.scatter[i].data();
    SymEigenvaluesNewtonBatch(columns, num_dense, 1e-9, b_.l1.data(), b_.l2.data(), b_.l3.data(),
                              b_.eigen_ok.data(), kernel_);
    for (int j = 0; j < num_dense; ++j) {
      if (b_.eigen_ok[j]) continue;
      double scatter[6];
      for (int i = 0; i < 6; ++i) scatter[i] = b_.scatter[i][j];
      SymEigenvalues3(scatter, b_.l1[j], b_.l2[j], b_.l3[j]);
    }
    // Every grid's smallest eigenvector, also in one batch (read only where the normal counts).
    double* const v1[3] = {b_.v1[0].data(), b_.v1[1].data(), b_.v1[2].data()};
    SmallestEigenvectorBatch(columns, b_.l1.data(), b_.l2.data(), b_.l3.data(), num_dense, v1,
                             b_.l1_refined.data(), kernel_);
    // The noise figures the rules branch on, also in one batch (read only where they count):
    // computed per grid inside the rules, their divisions and square roots held up the branches.
    const double* const w[6] = {b_.dense_w[0].data(), b_.dense_w[1].data(), b_.dense_w[2].data(),
                                b_.dense_w[3].data(), b_.dense_w[4].data(), b_.dense_w[5].data()};
    const double* const normals[3] = {v1[0], v1[1], v1[2]};
    GridNoiseBatch(b_.dense_k.data(), w, b_.l2.data(), normals, num_dense, eta_, params_.eta_sigmas,
                   b_.isotropic.data(), b_.tilt.data(), b_.effective.data(), b_.angle.data(),
                   kernel_);
  }

  /// The rules for the chunk's grid j: its class, and for a planar grid its plane and seed key.
  void ApplyRules(int j) {
    const bool depth_model = image_.depth_model;
    const int c = b_.dense[j];
    const MomentSums& s = cells_.sums[c];
    SymEigen3 e;
    e.l1 = b_.l1[j];
    e.l2 = b_.l2[j];
    e.l3 = b_.l3[j];
    if (e.l2 <= grid_.alpha * e.l3) {
      cells_.classes[c] = CellClass::kLinear;
      return;
    }
    const double iso = b_.isotropic[j];
    // The eigenvector only where it counts: the noise along the normal of a grid whose normal
    // is pure noise (tilt >= 1, most grids beyond 2-3 m) is its isotropic noise, and such a
    // grid gets no angle test either (see below).
    double tilt = b_.tilt[j];
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
      e.v1 = Eigen::Vector3d(b_.v1[0][j], b_.v1[1][j], b_.v1[2][j]);
      e.l1 = b_.l1_refined[j];
    }
    const double mse = e.l1 / s.k;
    // sigma_n,rms^2 (where have_normal holds, tilt is still the batch's, and so is the
    // effective MSE with it)
    const double noise_mse = have_normal ? b_.effective[j] : iso;
    bool planar = e.l1 <= grid_.beta * e.l2;
    if (!planar && depth_model) {
      planar = mse <= params_.planar_sigmas * params_.planar_sigmas * noise_mse;
    }
    if (!planar) {
      cells_.classes[c] = CellClass::kSpherical;
      return;
    }
    cells_.classes[c] = CellClass::kPlanar;
    CellInfo& ci = cells_.info[c];
    const Eigen::Vector3d centre = s.Centroid();
    ci.m = centre.cast<float>();
    if (depth_model) {
      // Normal noise of a small grid: std ~ sigma_n / sqrt(l2) [rad], from noise_mse (read
      // only where have_normal holds).
      const double ang = b_.angle[j];
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
      cells_.seeds.push_back(SeedKey(mse + iso * seed_tilt * seed_tilt, c));
    } else {
      ci.n = (e.v1.dot(centre) < 0 ? Eigen::Vector3d(-e.v1) : e.v1).cast<float>();
      ci.cos_tol = static_cast<float>(cos_eta_);
      cells_.seeds.push_back(SeedKey(mse, c));  // Algorithm 2 line 4: minimal MSE first
    }
    if (grid_.grid_level) cells_.seed_keys[c] = cells_.seeds.back();
  }

  const GridImage& image_;
  const DetectionParams& params_;
  const GridParams& grid_;
  CellMoments& cells_;
  ClassifyBatch& b_;
  SimdKernel kernel_;
  double eta_, cos_eta_;
};

/// Sizes `cells` for the frame (every entry written below, or filled here).
void Prepare(const GridImage& image, CellMoments& cells) {
  const int num_cells = image.num_cells;
  cells.sums.resize(num_cells);
  cells.noise_weight.resize(num_cells);
  cells.counts.resize(num_cells);
  cells.grid_rays.resize(image.params.ray_fit ? num_cells : 0);
  cells.partly_valid.resize(num_cells);
  cells.classes.assign(num_cells, CellClass::kSparse);
  cells.info.resize(num_cells);
  cells.seeds.clear();
  if (image.grid.grid_level) cells.seed_keys.resize(num_cells);
}

/// Each grid of the row starting at grid `row` (image rows [y0, y1)): its count, whether it is
/// partly valid (appended at num_partly_valid), and its noise moment W.
void FinishRowSums(const GridImage& image, CellMoments& cells, std::size_t row, int y0, int y1,
                   std::size_t& num_partly_valid) {
  const int k = image.k, width = image.width;
  const double s0 = image.params.sigma0, s2 = image.params.sigma_z2;
  for (std::size_t c = row; c < row + image.cells_x; ++c) {
    MomentSums& m = cells.sums[c];
    cells.counts[c] = static_cast<std::int32_t>(m.k);
    // Listed without a branch (the pixel labels mark their invalid pixels, ExpandToPixels).
    const int x0 = static_cast<int>(c - row) * k;
    const int pixels = (std::min(width, x0 + k) - x0) * (y1 - y0);
    cells.partly_valid[num_partly_valid] = static_cast<int>(c);
    num_partly_valid += m.k < pixels;
    if (m.k == 0) {
      cells.noise_weight[c] = 0.0;
      continue;
    }
    // Noise moment: W = w(z) Q with w = (sigma(z)/z)^2 at the grid's centre (within a k x k
    // grid z varies by ~1 %, so this equals the per-pixel sum to ~2 %; the pixels the
    // refinement moves carry their grid's weight too).
    const double z = image.spherical ? m.Centroid().norm() : m.sz / m.k;
    const double w = z > 0 ? (s0 + s2 * z * z) * (s0 + s2 * z * z) / (z * z) : 0.0;
    m.SetUniformNoise(w);
    cells.noise_weight[c] = w;
  }
}

}  // namespace

// Per-grid moments K, S, Q (10 sums) and the ray sums of a row of grids at a time, while its
// band of k image rows is in L1 (the final ray fit of a region then adds its grids' sums instead
// of visiting every pixel again); then each grid's noise moment W. Each row of grids is
// classified right after, while its sums are still in cache (with 3x3 grids the sums of a frame
// take megabytes).
double ComputeCellMoments(const GridImage& image, CellMoments& cells) {
  Prepare(image, cells);
  const DetectionParams& params = image.params;
  const SimdKernel kernel = FastestSimdKernel();
  ClassifyBatch& batch = internal::ThreadScratch<ClassifyBatch>();
  batch.Resize();
  Classifier classifier(image, cells, batch, kernel);
  std::size_t num_partly_valid = 0;
  double classify_ms = 0.0;
  for (int cy = 0; cy < image.cells_y; ++cy) {
    const int y0 = cy * image.k, y1 = std::min(image.height, y0 + image.k);
    const std::size_t row = static_cast<std::size_t>(cy) * image.cells_x;
    const bool last_row = cy + 1 == image.cells_y;
    const std::size_t next_row = row + image.cells_x;
    SumGridRow(image.pts, image.width, image.height, y0, y1, image.k, image.spherical, params,
               cells.sums.data() + row, params.ray_fit ? cells.grid_rays.data() + row : nullptr,
               kernel, last_row ? nullptr : cells.sums.data() + next_row,
               params.ray_fit && !last_row ? cells.grid_rays.data() + next_row : nullptr);
    FinishRowSums(image, cells, row, y0, y1, num_partly_valid);
    const auto tc = Clock::now();
    classifier.ClassifyRow(static_cast<int>(row), static_cast<int>(row) + image.cells_x);
    classify_ms += std::chrono::duration<double, std::milli>(Clock::now() - tc).count();
  }
  cells.partly_valid.resize(num_partly_valid);
  return classify_ms;
}

}  // namespace planeslam::detection::gbrg
