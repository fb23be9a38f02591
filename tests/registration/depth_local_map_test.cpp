// The depth camera's local map: per-pixel fusion weighted by the noise model, re-anchoring, and
// the corridor's axis held by the pipes and lamps over a randomized family of noise seeds.
#include "planeslam/registration/depth_local_map.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <string>

#include "planeslam/datasets/synthetic_sequence.hpp"
#include "planeslam/detection/grid_region_growing.hpp"
#include "planeslam/registration/plane_odometry.hpp"

namespace planeslam::registration {
namespace {

datasets::PinholeIntrinsics Camera(int width, int height) {
  datasets::PinholeIntrinsics k;
  k.width = width;
  k.height = height;
  k.fx = k.fy = 0.84 * width;
  k.cx = 0.5 * width - 0.3;
  k.cy = 0.5 * height + 0.2;
  return k;
}

/// A wall facing the camera at depth `depth` (camera frame), with the Kinect noise model along
/// the rays drawn from `rng`.
datasets::OrganizedCloud Wall(const datasets::PinholeIntrinsics& k, double depth, double sigma_z2,
                              std::mt19937& rng) {
  datasets::OrganizedCloud cloud(k.width, k.height, datasets::SensorModel::kPinhole);
  std::normal_distribution<double> g(0.0, 1.0);
  for (int r = 0; r < k.height; ++r) {
    for (int c = 0; c < k.width; ++c) {
      const double z = depth + sigma_z2 * depth * depth * g(rng);
      cloud.at(r, c) =
          Eigen::Vector3f(static_cast<float>((c - k.cx) / k.fx * z),
                          static_cast<float>((r - k.cy) / k.fy * z), static_cast<float>(z));
    }
  }
  return cloud;
}

/// RMS of the fused depth's error against a wall at `depth` in the reference frame, the mean
/// information and the number of pixels, over the pixels holding at least `min_weight`.
struct FusedStats {
  double rms = 1e9;
  double weight = 0.0;
  int pixels = 0;
};
FusedStats Fused(const DepthLocalMap& map, double depth, double min_weight = 0.0) {
  FusedStats s;
  double sq = 0.0, weight_sum = 0.0;
  for (int r = 0; r < map.intrinsics().height; ++r) {
    for (int c = 0; c < map.intrinsics().width; ++c) {
      Eigen::Vector3d p;
      double w = 0.0;
      if (!map.FusedPoint(r, c, &p, &w) || w < min_weight) continue;
      sq += (p.z() - depth) * (p.z() - depth);
      weight_sum += w;
      ++s.pixels;
    }
  }
  if (s.pixels > 0) {
    s.rms = std::sqrt(sq / s.pixels);
    s.weight = weight_sum / s.pixels;
  }
  return s;
}

TEST(DepthLocalMap, FusionAveragesTheNoiseAlongTheRay) {
  const datasets::PinholeIntrinsics k = Camera(80, 60);
  DepthMapConfig config;
  DepthLocalMap map(k, config);
  std::mt19937 rng(3);
  const double depth = 5.0, sigma = config.sigma_z2 * depth * depth;  // 3.6 cm per pixel
  const int frames = 25;
  for (int i = 0; i < frames; ++i)
    map.Insert(Wall(k, depth, config.sigma_z2, rng), nullptr, Pose::Identity());
  const FusedStats fused = Fused(map, depth);
  EXPECT_EQ(fused.pixels, k.width * k.height);
  // sigma / sqrt(25) = 7 mm; 20% margin for the sample's spread over 4800 pixels and the rare
  // sample beyond the fusion gate.
  EXPECT_LT(fused.rms, 1.2 * sigma / std::sqrt(frames));
  EXPECT_GT(fused.rms, 0.8 * sigma / std::sqrt(frames));
  EXPECT_NEAR(fused.weight, frames / (sigma * sigma), 0.05 * frames / (sigma * sigma));
}

TEST(DepthLocalMap, ReanchoringCarriesTheFusedSurface) {
  const datasets::PinholeIntrinsics k = Camera(80, 60);
  DepthMapConfig config;
  DepthLocalMap map(k, config);
  std::mt19937 rng(5);
  const double depth = 5.0;
  for (int i = 0; i < 20; ++i)
    map.Insert(Wall(k, depth, config.sigma_z2, rng), nullptr, Pose::Identity());
  // Step forward past the re-anchoring distance: the wall is nearer, and the fused surface moved
  // into the new view keeps its accuracy before the new frame is even averaged in.
  const double step = 1.5 * config.reanchor_distance;
  Pose T = Pose::Identity();
  T.translation().z() = step;
  map.Insert(Wall(k, depth - step, config.sigma_z2, rng), nullptr, T);
  EXPECT_TRUE(map.T_world_ref().isApprox(T));
  const double sigma_near = config.sigma_z2 * (depth - step) * (depth - step);
  // The pixels that received the moved surface (the old view, magnified, covers about half of
  // the new one; the new frame alone fills the rest) hold more than one frame's information and
  // are well below a single frame's noise.
  const FusedStats carried = Fused(map, depth - step, 2.0 / (sigma_near * sigma_near));
  EXPECT_GT(carried.pixels, k.width * k.height / 3);
  EXPECT_LT(carried.rms, 0.5 * sigma_near);
}

TEST(DepthLocalMap, EmptyOrMismatchedInputIsNotAnError) {
  const datasets::PinholeIntrinsics k = Camera(80, 60);
  DepthLocalMap map(k, {});
  map.Insert(datasets::OrganizedCloud(40, 30, datasets::SensorModel::kPinhole), nullptr,
             Pose::Identity());
  EXPECT_TRUE(map.empty());
  RegistrationResult reg;
  reg.degenerate = true;
  reg.degenerate_directions.push_back((Vector6d() << 1, 0, 0, 0, 0, 0).finished());
  reg.covariance = Matrix6d::Identity() * 1e-2;
  std::mt19937 rng(1);
  EXPECT_FALSE(
      FillDegenerateFromDepthMap(map, Pose::Identity(), Wall(k, 3.0, 1e-3, rng), nullptr, &reg));
  EXPECT_FALSE(reg.used_icp);
}

TEST(DepthLocalMap, ConfigValidation) {
  EXPECT_TRUE(DepthMapConfig{}.Validate().empty());
  DepthMapConfig bad;
  bad.sigma_z2 = 0.0;
  bad.query_stride = 0;
  EXPECT_EQ(bad.Validate().size(), 2u);
}

/// The synthetic corridor (config/sim_corridor.yaml's scene: pipes under the ceiling every 6 m, a
/// lamp 3 m after each, Kinect-like noise, 8 m range) at half resolution, its first `frames`
/// frames: the odometry's error along the axis at the end [m].
double CorridorAxisError(std::uint64_t seed, int frames) {
  datasets::SyntheticConfig config =
      datasets::SyntheticConfig::ForScene(datasets::SceneKind::kCorridor);
  config.seed = seed;
  config.pinhole.intrinsics = Camera(320, 240);
  const datasets::SyntheticSequence seq(config);
  detection::DetectionParams params;  // as config/detection_synthetic.yaml
  params.gamma = 0.007;
  params.epsilon_sigmas = 1.0;
  params.epsilon_count_sigmas = 1.5;
  params.merge_disjoint = true;
  const detection::GridRegionGrowing detector(params, detection::GridParams{});
  PlaneOdometry odo({}, *seq.GroundTruth(0));
  for (int i = 0; i < frames; ++i) {
    const datasets::Frame f = seq.Load(i);
    odo.Track(f.timestamp, f.cloud, detector);
  }
  const Pose gt = *seq.GroundTruth(frames - 1);
  return odo.T_world_sensor().translation().x() - gt.translation().x();
}

TEST(DepthLocalMap, CorridorAxisHeldOverNoiseSeeds) {
  // Three noise seeds, 2 m each (the camera passes under a lamp while a pipe comes into view):
  // every run within 1 cm along the axis (measured: a few millimetres). Failure budget: none of
  // the three.
  for (std::uint64_t seed = 1; seed <= 3; ++seed) {
    const double error = CorridorAxisError(seed, 120);
    RecordProperty("axis_error_m_seed_" + std::to_string(seed), std::to_string(error));
    EXPECT_LT(std::abs(error), 0.01) << "seed " << seed;
  }
}

}  // namespace
}  // namespace planeslam::registration
