#pragma once
/// Point-based region growing, PBRG (Xiao et al. 2011, Section II, Algorithm 1).
///
/// Points are visited in scan (row-major) order; a point already in any region (R or R') is
/// skipped. A point p_s is a seed when (a) among its 8 range-image neighbours (the 3x3 window, so
/// that seed + neighbours is the 3x3 grid of GBRG with the same minimum of 7 points) at least
/// `seed_neighbours` (paper: six) lie within delta of it in 3D, and (b) p_s with those neighbours
/// is planar by the grid shape test (alpha, beta; Section III-A). The seed and those neighbours
/// start the region GR, which grows breadth-first over 4-neighbours in the range image: a
/// neighbour p_c of a region point p_q with |p_c - p_q| < delta joins when
///   |n(GR u p_c) . p_c - d(GR u p_c)| < gamma  and  MSE(GR u p_c) < epsilon   (Alg. 1 line 9).
/// Regions of >= theta points are planes (R), smaller ones uncertain (R', Alg. 1 line 17 read as
/// R' <- R' u GR); points of R' leave PCD as in the paper (no seed, no growth into them).
///
/// Shared points: the paper lets a point on a joint belong to two planes. Here growth may enter
/// the points of earlier planes (they are tested like any other point), and such a shared point
/// is kept by the plane it fits best, |n.p - d| in units of each plane's tolerance at that point
/// (its moments move from one plane to the other). The label image stays a partition, and the
/// result does not hinge on which of two planes was grown first.
///
/// Incremental fit: with refit_interval = 1 the plane of GR u p_c is refitted for every tested
/// point, exactly as in the paper (one 3x3 eigen solve per test). With refit_interval = 0
/// (adaptive, the default) the plane is refitted after every max(1, K/64) accepted points; in
/// between, the distance test uses the current plane (which moves by O(1/K) per point) and the
/// MSE test first uses the MSE about the current normal n, n^T C' n / K', an upper bound of
/// MSE(GR u p_c) = lambda_min(C') / K'; only when that bound fails is the exact eigen solve done,
/// so the MSE test accepts exactly what the paper's accepts.
#include <string>

#include "planeslam/detection/detection_config.hpp"
#include "planeslam/detection/plane_detector.hpp"

namespace planeslam::detection {

struct PointParams {
  int seed_neighbours = 6;  ///< of the 8 window neighbours within delta (paper: six)
  double alpha = 0.006;     ///< seed shape test: linear when l2 <= alpha l3
  double beta = 0.4;        ///< seed shape test: planar when l1 <= beta l2
  int refit_interval = 0;   ///< 1 = refit for every test (paper); N = every N joins; 0 = adaptive
  std::vector<std::string> Validate() const;
};

class PointRegionGrowing : public PlaneDetector {
 public:
  PointRegionGrowing(const DetectionParams& params, const PointParams& point,
                     std::string name = "point");
  std::string Name() const override { return name_; }
  Segmentation Detect(const datasets::OrganizedCloud& cloud) const override;

 private:
  DetectionParams params_;
  PointParams point_;
  std::string name_;
};

}  // namespace planeslam::detection
