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
/// trace (Dijkstra). The search runs backwards from the target, so one search answers many
/// sources; it stops when every source is settled or after `max_nodes` settled nodes, and
/// sources it does not reach get no answer (the caller uses its own bound, e.g. the loop search's
/// drift prior).
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
  /// T_source_to for each of `sources`, in their order, from one search.
  std::vector<std::optional<UncertainPose>> RelativeFrom(const std::vector<std::int64_t>& sources,
                                                         std::int64_t to);

 private:
  /// The nodes are numbered densely in the order they first appear, so a search runs on arrays.
  /// A link of node u to node v is one direction of an edge; the search walks it backwards,
  /// from v to u, weighed by the covariance of the step from u to v.
  struct Link {
    int to;          ///< dense number of the other node
    int covariance;  ///< index in covariances_ of T_other_this's covariance (in `other`)
    double weight;   ///< trace of that covariance
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
  /// Settles nodes backwards from `target` until the `wanted` nodes flagged in reached_ are
  /// settled or the budget is spent.
  void SearchBack(int target, std::size_t wanted);

  const PoseGraph& graph_;
  std::size_t max_nodes_;
  std::unordered_map<std::int64_t, int> number_;
  std::vector<std::int64_t> ids_;
  std::vector<std::vector<Link>> links_;
  std::vector<Matrix6d> covariances_;  ///< of every link's step, both directions of each edge
  /// One search's state of a node, valid while its stamp is the search's (nothing is cleared
  /// between searches).
  struct Reached {
    std::uint32_t stamp = 0;
    bool settled = false;
    bool wanted = false;  ///< a source of the search
    double distance = 0.0;
    int next = -1;        ///< the node after this one on the path to the target
    int covariance = -1;  ///< of the step from this node to `next`
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
