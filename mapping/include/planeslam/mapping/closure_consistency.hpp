#pragma once
/// Loop closures as hypotheses: the consistency tests of pairwise consistency maximisation (PCM,
/// Mangelson et al. ICRA 2018) on relative poses with covariances.
///
/// Poses and covariances use the registration module's tangent convention (translation first,
/// translation additive and rotation left-perturbed in the frame the pose maps into), so a
/// registration's covariance enters unchanged. First-order propagation:
///
///     C = A B:   dC = J_A dA + J_B dB,   J_A = [I  -[R_A t_B]x; 0 I],   J_B = diag(R_A, R_A)
///     X^-1:      dX^-1 = J dX,           J = [-R^T  -R^T [t]x; 0 -R^T]
///
/// A closure Z_ij (old keyframe i, new keyframe j) is consistent with the trajectory when
/// Z_ij ~ T_ij, the estimate's relative pose, with the covariance of the closure plus that of the
/// estimate's path from i to j; two closures a, b are consistent with each other when the cycle
/// Z_a T_(ja jb) Z_b^-1 T_(ia ib)^-1 is the identity, with the covariances of its four legs. Both
/// are chi-square tests with 6 degrees of freedom.
#include <Eigen/Core>
#include <cstdint>
#include <optional>
#include <unordered_map>
#include <vector>

#include "planeslam/mapping/pose_graph.hpp"

namespace planeslam::mapping {

/// A relative pose with its covariance (tangent convention above).
struct UncertainPose {
  Pose T = Pose::Identity();
  Matrix6d covariance = Matrix6d::Zero();
};

/// a * b with the covariances propagated (the two taken as independent).
UncertainPose Compose(const UncertainPose& a, const UncertainPose& b);
/// x^-1 with its covariance.
UncertainPose Invert(const UncertainPose& x);
/// Chi-square of the deviation of `x` from the identity under its covariance (6 dof).
double IdentityChi2(const UncertainPose& x);

/// Relative poses between graph nodes with the uncertainty of the best-determined chain of edges
/// between them: the means come from the graph's current node poses, the covariance from the
/// edges (odometry and accepted closures) along the path that minimises the summed covariance
/// trace (Dijkstra). A search stops after `max_nodes` settled nodes; nodes it does not reach get
/// no answer (the caller uses its own bound, e.g. the loop search's drift prior).
class GraphPaths {
 public:
  /// Paths over the edges of `graph` (which must outlive this); edges added to or removed from
  /// the graph later are passed on with AddEdge / RemoveEdge.
  GraphPaths(const PoseGraph& graph, std::size_t max_nodes);
  void AddEdge(const PoseGraphEdge& edge);
  /// Removes the links of one edge between `from` and `to`.
  void RemoveEdge(std::int64_t from, std::int64_t to);
  /// T_from_to and its covariance, or nothing when `to` is not reached from `from`.
  std::optional<UncertainPose> Relative(std::int64_t from, std::int64_t to);

 private:
  /// The nodes are numbered densely in the order they first appear, so a search runs on arrays.
  struct Link {
    int to;               ///< dense number of the node
    Matrix6d covariance;  ///< of T_from_to, in `from`
    double weight;        ///< trace of the covariance
  };
  struct Queued {
    double distance;
    std::int64_t id;  ///< ties are broken by node id
    int node;
    bool operator>(const Queued& o) const {
      return distance > o.distance || (distance == o.distance && id > o.id);
    }
  };
  int Number(std::int64_t id);      ///< the node's dense number, added when new
  int Find(std::int64_t id) const;  ///< or -1

  const PoseGraph& graph_;
  std::size_t max_nodes_;
  std::unordered_map<std::int64_t, int> number_;
  std::vector<std::int64_t> ids_;
  std::vector<std::vector<Link>> links_;
  /// One search's state of a node, valid while its stamp is the search's (nothing is cleared
  /// between searches).
  struct Reached {
    std::uint32_t stamp = 0;
    double distance = 0.0;
    int previous = -1;
    const Link* via = nullptr;
  };
  std::vector<Reached> reached_;
  std::vector<Queued> queue_;
  std::uint32_t search_ = 0;
};

/// Nodes of the largest clique of an undirected graph given by its adjacency matrix (symmetric,
/// diagonal ignored), exact (branch and bound with a greedy colouring bound, Tomita & Seki); meant
/// for the few tens of hypotheses of a window. The indices come sorted.
std::vector<int> MaximumClique(const std::vector<std::vector<bool>>& adjacent);

}  // namespace planeslam::mapping
