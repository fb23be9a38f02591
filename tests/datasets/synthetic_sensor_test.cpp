// Simulated sensors: the fast culled ray casters against the brute-force reference, labels against
// the exact planes, the noise and dropout models, determinism, and the corridor's degeneracy.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>

#include <cmath>
#include <cstring>
#include <map>
#include <random>

#include "planeslam/datasets/synthetic_sequence.hpp"

namespace planeslam::datasets {
namespace {

constexpr double kPi = 3.14159265358979323846;

/// Every first hit kept: no noise, no dropouts, no range limits.
SyntheticConfig RawConfig(SceneKind kind, const std::string& sensor) {
  SyntheticConfig c = SyntheticConfig::ForScene(kind);
  c.sensor = sensor;
  c.pinhole.noise = false;
  c.pinhole.edge_dropout = false;
  c.pinhole.max_incidence_deg = 90.0;
  c.pinhole.min_depth = 0.0;
  c.pinhole.max_depth = 1e9;
  c.spherical.noise = false;
  c.spherical.max_incidence_deg = 90.0;
  c.spherical.min_range = 0.0;
  c.spherical.max_range = 1e9;
  c.trajectory.frames = 8;
  return c;
}

/// True when p lies on the surface a hit with `label` would be on (a plane, or any curved one).
bool OnSurface(const SyntheticScene& scene, int label, const Eigen::Vector3d& p, double tol) {
  if (label > 0) {
    const ScenePlane& plane = scene.Plane(label);
    return std::abs(plane.normal.dot(p) - plane.d) <= tol;
  }
  for (const auto& s : scene.spheres)
    if (std::abs((p - s.center).norm() - s.radius) <= tol) return true;
  for (const auto& c : scene.cylinders) {
    const Eigen::Vector3d w = p - c.base;
    if (std::abs((w - w.dot(c.axis) * c.axis).norm() - c.radius) <= tol) return true;
  }
  return false;
}

void CompareWithBruteForce(SceneKind kind, const std::string& sensor_name) {
  SyntheticSequence seq(RawConfig(kind, sensor_name));
  const SyntheticScene& scene = seq.scene();
  const SyntheticSensor& sensor = seq.sensor();
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  Eigen::AlignedBox3d box = scene.Bounds();
  if (kind == SceneKind::kCorridor) box.max().x() = 12.0;  // keep poses near the camera run
  if (kind == SceneKind::kRubble) {  // around the pile, above the ground
    box.min() = Eigen::Vector3d(-4, -4, 0.05);
    box.max() = Eigen::Vector3d(4, 4, 2.5);
  }
  int compared = 0, ties = 0, misses = 0;
  for (int pose_i = 0; pose_i < 6; ++pose_i) {
    Pose T = Pose::Identity();
    for (int a = 0; a < 3; ++a) {
      T.translation()[a] = box.min()[a] + (0.05 + 0.9 * u01(rng)) * box.sizes()[a];
    }
    std::normal_distribution<double> g;
    T.linear() = Eigen::Quaterniond(g(rng), g(rng), g(rng), g(rng)).normalized().toRotationMatrix();
    const SyntheticRender render = sensor.Render(T, 1);
    for (int k = 0; k < 4000; ++k) {
      const int r = static_cast<int>(u01(rng) * sensor.Height());
      const int c = static_cast<int>(u01(rng) * sensor.Width());
      const std::size_t i = static_cast<std::size_t>(r) * sensor.Width() + c;
      const Eigen::Vector3d d_sensor = sensor.RayDirection(r, c);
      const Eigen::Vector3d d = T.linear() * d_sensor;
      const RayHit ref = IntersectScene(scene, T.translation(), d);
      if (!ref.hit) {
        EXPECT_TRUE(std::isnan(render.true_range[i])) << r << "," << c;
        ++misses;
        continue;
      }
      // Pinhole stores depth z = t * d_z; the scanner stores the range t.
      const double expected = sensor.Model() == SensorModel::kPinhole ? ref.t * d_sensor.z() : ref.t;
      ASSERT_FALSE(std::isnan(render.true_range[i])) << r << "," << c;
      EXPECT_NEAR(render.true_range[i], expected, 1e-6 * expected) << r << "," << c;
      const int label = render.labels.data[i];
      const Eigen::Vector3d p = T.translation() + ref.t * d;
      if (label != ref.label) {
        // Only a tie on a shared edge may pick another face: the point lies on both.
        EXPECT_TRUE(OnSurface(scene, label, p, 1e-6 * std::max(1.0, ref.t)))
            << scene.name << " label " << label << " vs " << ref.label << " at " << p.transpose();
        ++ties;
      }
      // The measured point (no noise) is the exact hit.
      const Eigen::Vector3d q = T * render.cloud.points[i].cast<double>();
      EXPECT_LE((q - p).norm(), 1e-6 * std::max(1.0, ref.t));
      ++compared;
    }
  }
  EXPECT_GT(compared, 5000) << scene.name;  // rays into the open sky are not compared
  EXPECT_LT(ties, compared / 100) << scene.name;
  (void)misses;
}

TEST(SyntheticSensor, PinholeMatchesBruteForceRoom) { CompareWithBruteForce(SceneKind::kRoom, "pinhole"); }
TEST(SyntheticSensor, PinholeMatchesBruteForceCorridor) {
  CompareWithBruteForce(SceneKind::kCorridor, "pinhole");
}
TEST(SyntheticSensor, PinholeMatchesBruteForceRubble) {
  CompareWithBruteForce(SceneKind::kRubble, "pinhole");
}
TEST(SyntheticSensor, SphericalMatchesBruteForceRoom) {
  CompareWithBruteForce(SceneKind::kRoom, "spherical");
}
TEST(SyntheticSensor, SphericalMatchesBruteForceRubble) {
  CompareWithBruteForce(SceneKind::kRubble, "spherical");
}

// A primitive beyond max_depth in range can still lie within it in depth z (off-axis pixels):
// the far-primitive cull must not drop it.
TEST(SyntheticSensor, OffAxisObjectWithinDepthButBeyondRangeIsSeen) {
  PinholeSimConfig config;
  config.noise = false;
  config.edge_dropout = false;
  const PinholeIntrinsics& K = config.intrinsics;
  const Eigen::Vector3d D((620 - K.cx) / K.fx, (460 - K.cy) / K.fy, 1.0);
  SyntheticScene scene;
  scene.spheres.push_back({9.0 * D.normalized(), 0.2});  // range 8.8..9.2 m, depth about 7.4 m
  const auto sensor = MakePinholeSensor(scene, config);
  const SyntheticRender render = sensor->Render(Pose::Identity(), 1);
  const std::size_t i = 460u * K.width + 620u;
  const RayHit ref = IntersectScene(scene, Eigen::Vector3d::Zero(), D.normalized());
  ASSERT_TRUE(ref.hit);
  const double z = ref.t / D.norm();
  ASSERT_LT(z, config.max_depth);
  ASSERT_GT(ref.t, config.max_depth);
  EXPECT_NEAR(render.true_range[i], z, 1e-6 * z);
  EXPECT_TRUE(OrganizedCloud::IsValid(render.cloud.points[i]));
}

/// Checks every labelled pixel against its plane: distance <= bound(z).
template <class Bound>
void CheckLabelsOnPlanes(const SyntheticSequence& seq, Bound bound, double min_labelled) {
  const std::size_t n = seq.Size();
  for (std::size_t f : {std::size_t{0}, n / 4, n / 2, 3 * n / 4}) {
    const SyntheticFrame frame = seq.Generate(f);
    const Pose T = *frame.frame.T_world_sensor_gt;
    std::size_t labelled = 0;
    double worst = 0.0;
    for (std::size_t i = 0; i < frame.labels.data.size(); ++i) {
      const int k = frame.labels.data[i];
      const Eigen::Vector3f& pf = frame.frame.cloud.points[i];
      if (k == 0) continue;
      ASSERT_TRUE(OrganizedCloud::IsValid(pf)) << "label on an invalid pixel";
      const ScenePlane& plane = seq.scene().Plane(k);
      const Eigen::Vector3d p = T * pf.cast<double>();
      const double dist = std::abs(plane.normal.dot(p) - plane.d);
      const double z = seq.sensor().Model() == SensorModel::kPinhole ? pf.z() : pf.norm();
      worst = std::max(worst, dist / bound(z));
      ++labelled;
    }
    EXPECT_LE(worst, 1.0) << seq.Name() << " frame " << f;
    EXPECT_GT(static_cast<double>(labelled), min_labelled * frame.labels.data.size())
        << seq.Name() << " frame " << f;
  }
}

TEST(SyntheticSensor, LabelledPixelsLieOnTheirPlanes) {
  for (SceneKind kind : {SceneKind::kRoom, SceneKind::kRubble}) {
    SyntheticConfig config = SyntheticConfig::ForScene(kind);
    const double k = config.pinhole.noise_k;
    // With noise: within 4 sigma(z) = 4 k z^2 (noise is truncated at 3 sigma along the ray).
    CheckLabelsOnPlanes(SyntheticSequence(config), [k](double z) { return 4.0 * k * z * z; },
                        kind == SceneKind::kRoom ? 0.8 : 0.3);
    // Without noise: exactly on the plane (float storage of the points: 1e-6 relative).
    config.pinhole.noise = false;
    CheckLabelsOnPlanes(SyntheticSequence(config), [](double z) { return 1e-6 * z; },
                        kind == SceneKind::kRoom ? 0.8 : 0.3);
  }
}

TEST(SyntheticSensor, SphericalLabelsLieOnTheirPlanes) {
  SyntheticConfig config = SyntheticConfig::ForScene(SceneKind::kRoom);
  config.sensor = "spherical";
  const double sigma = config.spherical.range_sigma;
  CheckLabelsOnPlanes(SyntheticSequence(config), [sigma](double) { return 4.0 * sigma; }, 0.8);
  config.spherical.noise = false;
  CheckLabelsOnPlanes(SyntheticSequence(config), [](double z) { return 1e-6 * z; }, 0.8);
  const SyntheticFrame f = SyntheticSequence(config).Generate(0);
  EXPECT_EQ(f.frame.cloud.model, SensorModel::kSpherical);
  EXPECT_EQ(f.frame.cloud.width, 720);
  EXPECT_EQ(f.frame.cloud.height, 181);
}

TEST(SyntheticSensor, NoiseHasTheConfiguredSpread) {
  SyntheticConfig config = SyntheticConfig::ForScene(SceneKind::kRoom);
  config.pinhole.edge_dropout = false;
  SyntheticSequence seq(config);
  const SyntheticFrame f = seq.Generate(10);
  // Normalised depth errors e = (z - z_true) / sigma(z_true): truncated N(0,1) at 3 sigma.
  double sum = 0, sum2 = 0, max_abs = 0;
  std::size_t n = 0;
  for (std::size_t i = 0; i < f.true_range.size(); ++i) {
    const Eigen::Vector3f& p = f.frame.cloud.points[i];
    if (!OrganizedCloud::IsValid(p)) continue;
    const double zt = f.true_range[i];
    const double e = (p.z() - zt) / (config.pinhole.noise_k * zt * zt);
    sum += e;
    sum2 += e * e;
    max_abs = std::max(max_abs, std::abs(e));
    ++n;
  }
  ASSERT_GT(n, 100000u);
  const double mean = sum / n, var = sum2 / n - mean * mean;
  EXPECT_NEAR(mean, 0.0, 0.02);
  // Variance of N(0,1) truncated at +-3: 1 - 6 phi(3) / (1 - 2 Phi(-3)) = 0.9733.
  EXPECT_NEAR(var, 0.9733, 0.02);
  EXPECT_LE(max_abs, 3.0 + 1e-3);  // float storage of z
}

TEST(SyntheticSensor, DropoutsFollowTheModel) {
  SyntheticConfig config = SyntheticConfig::ForScene(SceneKind::kRoom);
  config.pinhole.noise = false;
  SyntheticSequence seq(config);
  const SyntheticSensor& sensor = seq.sensor();
  const double cos_max = std::cos(config.pinhole.max_incidence_deg * kPi / 180.0);
  for (std::size_t f : {std::size_t{0}, seq.Size() / 3}) {
    const SyntheticFrame frame = seq.Generate(f);
    const Pose T = *frame.frame.T_world_sensor_gt;
    const int w = sensor.Width(), h = sensor.Height();
    std::size_t dropped_edges = 0;
    for (int r = 0; r < h; ++r) {
      for (int c = 0; c < w; ++c) {
        const std::size_t i = static_cast<std::size_t>(r) * w + c;
        const Eigen::Vector3f& p = frame.frame.cloud.points[i];
        const float z = frame.true_range[i];
        if (!OrganizedCloud::IsValid(p)) {
          dropped_edges += !std::isnan(z);
          continue;
        }
        EXPECT_GE(p.z(), config.pinhole.min_depth);
        EXPECT_LE(p.z(), config.pinhole.max_depth);
        // Not on a depth discontinuity.
        for (auto [rr, cc] : {std::pair{r, c + 1}, {r + 1, c}, {r, c - 1}, {r - 1, c}}) {
          if (rr < 0 || cc < 0 || rr >= h || cc >= w) continue;
          const float zn = frame.true_range[static_cast<std::size_t>(rr) * w + cc];
          if (std::isnan(zn)) continue;
          EXPECT_LE(std::abs(zn - z), config.pinhole.edge_jump * std::min(z, zn) * (1 + 1e-6));
        }
        // Incidence within the limit for planar hits.
        const int k = frame.labels.data[i];
        if (k > 0) {
          const Eigen::Vector3d d = T.linear() * sensor.RayDirection(r, c);
          EXPECT_GE(std::abs(seq.scene().Plane(k).normal.dot(d)), cos_max - 1e-9);
        }
      }
    }
    EXPECT_GT(dropped_edges, 0u);  // the room has discontinuities in view
  }
}

TEST(SyntheticSensor, DisparityQuantisationGivesKinectSteps) {
  SyntheticConfig config = SyntheticConfig::ForScene(SceneKind::kRoom);
  config.pinhole.noise = false;
  config.pinhole.quantize_disparity = true;
  const SyntheticFrame f = SyntheticSequence(config).Generate(0);
  const double fb8 = config.pinhole.intrinsics.fx * config.pinhole.baseline * 8.0;
  std::size_t n = 0;
  for (std::size_t i = 0; i < f.true_range.size(); ++i) {
    const Eigen::Vector3f& p = f.frame.cloud.points[i];
    if (!OrganizedCloud::IsValid(p)) continue;
    const double steps = fb8 / p.z();
    EXPECT_NEAR(steps, std::round(steps), 1e-4 * steps);
    // Rounding the disparity moves z by at most half a step: z^2 / (2 * 8 f b).
    EXPECT_LE(std::abs(p.z() - f.true_range[i]), 0.5 * p.z() * f.true_range[i] / fb8 * 1.0001);
    ++n;
  }
  EXPECT_GT(n, 100000u);
}

TEST(SyntheticSequence, SameSeedSameBytesAnyOrder) {
  SyntheticConfig config = SyntheticConfig::ForScene(SceneKind::kRubble);
  config.pinhole.dropout_rate = 0.01;
  const SyntheticSequence a(config), b(config);
  const SyntheticFrame b7 = b.Generate(7);  // b renders in another order
  const SyntheticFrame a3 = a.Generate(3), a7 = a.Generate(7), b3 = b.Generate(3);
  auto same = [](const SyntheticFrame& x, const SyntheticFrame& y) {
    return x.frame.cloud.points.size() == y.frame.cloud.points.size() &&
           std::memcmp(x.frame.cloud.points.data(), y.frame.cloud.points.data(),
                       x.frame.cloud.points.size() * sizeof(Eigen::Vector3f)) == 0 &&
           x.labels.data == y.labels.data;
  };
  EXPECT_TRUE(same(a3, b3));
  EXPECT_TRUE(same(a7, b7));
  EXPECT_FALSE(same(a3, a7));
  config.seed = 2;
  EXPECT_FALSE(same(a3, SyntheticSequence(config).Generate(3)));
  EXPECT_EQ(a.GroundTruth(3)->matrix(), b3.frame.T_world_sensor_gt->matrix());
  EXPECT_EQ(a.Timestamp(3), b3.frame.timestamp);
  EXPECT_EQ(a.Load(3).cloud.CountValid(), a3.frame.cloud.CountValid());
}

/// Plane normals seen over a corridor run: the information they give about translation.
TEST(SyntheticSequence, CorridorLeavesTranslationAlongItsAxisUnobservable) {
  for (const std::string sensor : {"pinhole", "spherical"}) {
    SyntheticConfig config = SyntheticConfig::ForScene(SceneKind::kCorridor);
    config.sensor = sensor;
    SyntheticSequence seq(config);
    std::map<int, std::size_t> pixels;
    for (std::size_t f = 0; f < seq.Size(); f += 25) {
      for (std::uint16_t k : seq.Labels(f).data)
        if (k > 0) ++pixels[k];
    }
    Eigen::Matrix3d info = Eigen::Matrix3d::Zero();
    int planes = 0;
    for (const auto& [k, count] : pixels) {
      if (count < 100) continue;
      const Eigen::Vector3d n = seq.scene().Plane(k).normal;
      info += n * n.transpose();
      ++planes;
    }
    EXPECT_GE(planes, 3) << sensor;
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(info);
    // Rank 2: two clearly positive eigenvalues, one zero, its eigenvector the corridor axis x.
    EXPECT_GT(eig.eigenvalues()(1), 0.5) << sensor;
    EXPECT_LT(eig.eigenvalues()(0), 1e-12 * eig.eigenvalues()(2)) << sensor;
    EXPECT_GT(std::abs(eig.eigenvectors().col(0).dot(Eigen::Vector3d::UnitX())), 1.0 - 1e-12);
  }
}

}  // namespace
}  // namespace planeslam::datasets
