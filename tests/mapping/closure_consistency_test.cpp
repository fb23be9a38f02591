// Loop closures as hypotheses: the maximum clique (against brute force on random graphs), the
// first-order propagation of Compose / Invert (against finite differences), the chi-square of a
// cycle, and the graph's chain covariances (against every path of small random graphs).
#include "planeslam/mapping/closure_consistency.hpp"

#include <gtest/gtest.h>

#include <functional>
#include <random>

#include "planeslam/registration/geometry.hpp"

namespace planeslam::mapping {
namespace {

using registration::BoxMinus;
using registration::BoxPlus;

std::size_t BruteForceClique(const std::vector<std::vector<bool>>& adjacent) {
  const std::size_t n = adjacent.size();
  std::size_t best = 0;
  for (std::uint32_t mask = 1; mask < (1u << n); ++mask) {
    bool clique = true;
    for (std::size_t i = 0; i < n && clique; ++i) {
      for (std::size_t j = i + 1; j < n && clique; ++j) {
        if ((mask >> i & 1) && (mask >> j & 1) && !adjacent[i][j]) clique = false;
      }
    }
    if (clique) best = std::max<std::size_t>(best, __builtin_popcount(mask));
  }
  return best;
}

TEST(MaximumClique, MatchesBruteForceOnRandomGraphs) {
  std::mt19937_64 rng(7);
  for (int draw = 0; draw < 200; ++draw) {
    const std::size_t n = 1 + rng() % 14;
    const double density = 0.2 + 0.7 * static_cast<double>(rng() % 1000) / 1000.0;
    std::vector<std::vector<bool>> adjacent(n, std::vector<bool>(n, false));
    for (std::size_t i = 0; i < n; ++i) {
      for (std::size_t j = i + 1; j < n; ++j) {
        adjacent[i][j] = adjacent[j][i] = static_cast<double>(rng() % 1000) / 1000.0 < density;
      }
    }
    const std::vector<int> clique = MaximumClique(adjacent);
    ASSERT_EQ(clique.size(), BruteForceClique(adjacent)) << "draw " << draw;
    for (std::size_t a = 0; a < clique.size(); ++a) {
      for (std::size_t b = a + 1; b < clique.size(); ++b) {
        ASSERT_TRUE(adjacent[clique[a]][clique[b]]);
      }
    }
  }
}

Pose RandomPose(std::mt19937_64& rng, double scale) {
  std::normal_distribution<double> normal(0.0, 1.0);
  Vector6d x;
  for (int k = 0; k < 6; ++k) x[k] = scale * normal(rng);
  return BoxPlus(Pose::Identity(), x);
}

/// Jacobian of f at the identity perturbation, by central differences in the tangent convention.
template <typename F>
Matrix6d NumericJacobian(const F& f, const Pose& at) {
  Matrix6d J;
  const Pose f0 = f(at);
  for (int k = 0; k < 6; ++k) {
    Vector6d h = Vector6d::Zero();
    h[k] = 1e-6;
    J.col(k) = (BoxMinus(f(BoxPlus(at, h)), f0) - BoxMinus(f(BoxPlus(at, -h)), f0)) / 2e-6;
  }
  return J;
}

TEST(ClosureConsistency, ComposeAndInvertPropagateLikeFiniteDifferences) {
  std::mt19937_64 rng(3);
  for (int draw = 0; draw < 20; ++draw) {
    const Pose A = RandomPose(rng, 1.0), B = RandomPose(rng, 1.0);
    const Matrix6d Ja = NumericJacobian([&](const Pose& a) { return a * B; }, A);
    const Matrix6d Jb = NumericJacobian([&](const Pose& b) { return A * b; }, B);
    const Matrix6d Ji = NumericJacobian([](const Pose& x) { return x.inverse(); }, A);
    // Covariances with one unit direction each reveal the propagated Jacobian's columns.
    for (int k = 0; k < 6; ++k) {
      Matrix6d unit = Matrix6d::Zero();
      unit(k, k) = 1.0;
      const UncertainPose a{A, unit}, b{B, unit};
      const Matrix6d via_a = Compose(a, UncertainPose{B, Matrix6d::Zero()}).covariance;
      const Matrix6d via_b = Compose(UncertainPose{A, Matrix6d::Zero()}, b).covariance;
      const Matrix6d via_inverse = Invert(a).covariance;
      EXPECT_LT((via_a - Ja.col(k) * Ja.col(k).transpose()).cwiseAbs().maxCoeff(), 1e-5);
      EXPECT_LT((via_b - Jb.col(k) * Jb.col(k).transpose()).cwiseAbs().maxCoeff(), 1e-5);
      EXPECT_LT((via_inverse - Ji.col(k) * Ji.col(k).transpose()).cwiseAbs().maxCoeff(), 1e-5);
    }
  }
}

/// A square loop of four 1 m odometry edges (1 cm, 0.5 deg each) and the closure from the last
/// node to the first, true or off by `error`.
TEST(ClosureConsistency, CycleChiSquareSeparatesTrueFromFalseClosures) {
  PoseGraph graph;
  Pose T = Pose::Identity();
  const Pose step = BoxPlus(Pose::Identity(), (Vector6d() << 1, 0, 0, 0, 0, M_PI / 2).finished());
  const Matrix6d odometry_cov =
      (Vector6d() << 1e-4, 1e-4, 1e-4, 7.6e-5, 7.6e-5, 7.6e-5).finished().asDiagonal();
  for (int k = 0; k <= 4; ++k) {
    graph.AddNode(k, T, k == 0);
    if (k > 0) graph.AddEdge(k - 1, k, step, odometry_cov.inverse(), EdgeKind::kOdometry);
    T = T * step;
  }
  GraphPaths paths(graph, 100);
  const auto chain = paths.Relative(0, 4);
  ASSERT_TRUE(chain.has_value());
  EXPECT_LT(BoxMinus(chain->T, Pose::Identity()).norm(), 1e-9);  // the square closes
  const Matrix6d closure_cov = 0.01 * odometry_cov;
  const auto chi2 = [&](const Vector6d& error) {
    const UncertainPose closure{BoxPlus(Pose::Identity(), error), closure_cov};
    return IdentityChi2(Compose(Invert(*chain), closure));
  };
  EXPECT_LT(chi2(Vector6d::Zero()), 1e-9);
  // 1 cm off is within the four edges' uncertainty; 30 cm is not.
  EXPECT_LT(chi2((Vector6d() << 0.01, 0, 0, 0, 0, 0).finished()), 22.46);
  EXPECT_GT(chi2((Vector6d() << 0.3, 0, 0, 0, 0, 0).finished()), 22.46);
  // A shortcut edge with a tight covariance is the chain the search prefers.
  graph.AddEdge(0, 4, Pose::Identity(), (0.01 * odometry_cov).inverse(), EdgeKind::kLoopClosure);
  paths.AddEdge(graph.edges().back());
  EXPECT_LT(paths.Relative(0, 4)->covariance.trace(), chain->covariance.trace() / 10.0);
  paths.RemoveEdge(0, 4);
  EXPECT_NEAR(paths.Relative(0, 4)->covariance.trace(), chain->covariance.trace(), 1e-12);
  EXPECT_FALSE(GraphPaths(graph, 2).Relative(0, 3).has_value());  // beyond the node budget
}

/// Random graphs of 9 nodes (one without edges) and random edge covariances: one backward search
/// from a target answers every source with the chain of least summed covariance trace, found
/// here by walking every simple path, and agrees with a search per source.
TEST(ClosureConsistency, ChainsFromManySourcesAreTheLeastUncertainPaths) {
  std::mt19937 rng(31);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  constexpr int kNodes = 9, kIsolated = 8;
  for (int draw = 0; draw < 40; ++draw) {
    PoseGraph graph;
    for (int k = 0; k < kNodes; ++k) {
      graph.AddNode(k,
                    BoxPlus(Pose::Identity(), 3.0 * Vector6d::NullaryExpr([&] { return u(rng); })),
                    k == 0);
    }
    for (int k = 1; k < kIsolated; ++k) {  // a chain keeps the graph connected
      graph.AddEdge(k - 1, k, Pose::Identity(), Matrix6d::Identity(), EdgeKind::kOdometry);
    }
    for (int extra = 0; extra < 7; ++extra) {
      const int a = static_cast<int>(rng() % kIsolated), b = static_cast<int>(rng() % kIsolated);
      if (a == b) continue;
      graph.AddEdge(a, b, Pose::Identity(), Matrix6d::Identity(), EdgeKind::kLoopClosure);
    }
    for (PoseGraphEdge& edge : graph.edges()) {  // random covariances, random step poses
      const Matrix6d m = Matrix6d::NullaryExpr([&] { return u(rng); });
      edge.information = (m * m.transpose() + 0.1 * Matrix6d::Identity()).inverse();
      const Pose T = BoxPlus(Pose::Identity(), Vector6d::NullaryExpr([&] { return u(rng); }));
      edge.translation = T.translation();
      edge.rotation = Eigen::Quaterniond(T.linear());
    }
    GraphPaths paths(graph, 100);
    // Every step of each edge in both directions, as the search weighs it.
    std::vector<std::vector<std::pair<int, UncertainPose>>> steps(kNodes);
    for (const PoseGraphEdge& edge : graph.edges()) {
      const UncertainPose forward{edge.T_a_b(), edge.information.inverse()};
      steps[edge.from].push_back({static_cast<int>(edge.to), forward});
      steps[edge.to].push_back({static_cast<int>(edge.from), Invert(forward)});
    }
    const int target = static_cast<int>(rng() % kIsolated);
    std::vector<std::int64_t> sources;
    for (int k = 0; k < kNodes; ++k) sources.push_back(k);
    sources.push_back(sources[1]);  // a source twice
    const auto found = paths.RelativeFrom(sources, target);
    ASSERT_EQ(found.size(), sources.size());
    for (std::size_t k = 0; k < sources.size(); ++k) {
      const int source = static_cast<int>(sources[k]);
      const auto single = paths.Relative(source, target);
      if (source == kIsolated) {
        EXPECT_FALSE(found[k].has_value());
        EXPECT_FALSE(single.has_value());
        continue;
      }
      ASSERT_TRUE(found[k].has_value() && single.has_value());
      EXPECT_LT((found[k]->covariance - single->covariance).norm(), 1e-12);
      // The least uncertain chain by walking every simple path.
      double best = std::numeric_limits<double>::infinity();
      UncertainPose best_chain;
      std::vector<bool> visited(kNodes, false);
      const std::function<void(int, double, const UncertainPose&)> walk =
          [&](int node, double weight, const UncertainPose& chain) {
            if (node == target) {
              if (weight < best) {
                best = weight;
                best_chain = chain;
              }
              return;
            }
            visited[node] = true;
            for (const auto& [next, step] : steps[node]) {
              if (visited[next]) continue;
              // The means of a chain come from the node poses, the covariances from the edges.
              const UncertainPose placed{
                  graph.node(node).T_world_node().inverse() * graph.node(next).T_world_node(),
                  step.covariance};
              walk(next, weight + step.covariance.trace(), Compose(chain, placed));
            }
            visited[node] = false;
          };
      walk(source, 0.0, UncertainPose{});
      const Pose T_expected =
          graph.node(source).T_world_node().inverse() * graph.node(target).T_world_node();
      EXPECT_LT(BoxMinus(found[k]->T, T_expected).norm(), 1e-9);
      EXPECT_LE((found[k]->covariance - best_chain.covariance).norm(),
                1e-9 * best_chain.covariance.norm())
          << "draw " << draw << " source " << source << " target " << target;
    }
  }
}

}  // namespace
}  // namespace planeslam::mapping
