#pragma once
/// Pose graph: poses (nodes) linked by relative pose measurements (edges), optimised with Ceres.
///
/// Residual of an edge a -> b with measurement (p_ab, q_ab), as in Ceres'
/// examples/slam/pose_graph_3d:
///
///     r = U [ q_a^-1 (p_b - p_a) - p_ab ;  2 vec(q_ab * (q_a^-1 q_b)^-1) ]
///
/// with U the upper Cholesky factor of the edge's information (U^T U = information), so that
/// |r|^2 = e^T information e. Order of the 6 components: x y z, then rotation (about 1 rad per unit
/// for small angles, since 2 vec(q) ~ angle * axis). Information matrices in this module are in
/// this convention; g2o's rotation error is vec(q) (half of ours), see g2o_io.hpp for the
/// conversion.
///
/// Ceres stays out of this header (mapping links it privately).
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstddef>
#include <cstdint>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "planeslam/datasets/trajectory.hpp"

namespace planeslam::mapping {

using Matrix6d = Eigen::Matrix<double, 6, 6>;
using Vector6d = Eigen::Matrix<double, 6, 1>;

/// One pose of the graph. Position and quaternion are kept as given (not re-normalised) so that a
/// graph read from a file and written back reproduces the file's numbers exactly.
struct PoseGraphNode {
  std::int64_t id = 0;
  Eigen::Vector3d position = Eigen::Vector3d::Zero();            ///< p_world_node [m]
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();  ///< q_world_node
  bool fixed = false;  ///< held constant by the optimiser (g2o FIX)

  /// T_world_node (the quaternion is normalised on the way).
  Pose T_world_node() const;
  void SetPose(const Pose& T_world_node);
};

enum class EdgeKind { kOdometry, kLoopClosure };

/// A relative pose measurement T_a_b between nodes `from` (a) and `to` (b).
struct PoseGraphEdge {
  std::int64_t from = 0;
  std::int64_t to = 0;
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();         ///< p_ab [m]
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();  ///< q_ab
  /// Inverse covariance of the residual (x y z [1/m^2], rotation [1/rad^2]), symmetric positive
  /// definite, in this module's residual convention (see the file comment).
  Matrix6d information = Matrix6d::Identity();
  EdgeKind kind = EdgeKind::kOdometry;

  Pose T_a_b() const;
  void SetMeasurement(const Pose& T_a_b);
};

/// Nodes in insertion order plus edges; node ids are unique.
class PoseGraph {
 public:
  /// Adds a node; throws CheckError when the id exists (a bug in the caller; file readers check
  /// first and report IoError).
  void AddNode(std::int64_t id, const Pose& T_world_node, bool fixed = false);
  void AddNode(const PoseGraphNode& node);
  /// Adds an edge; both ends must exist and the information must be symmetric positive definite
  /// (CheckError otherwise).
  void AddEdge(const PoseGraphEdge& edge);
  void AddEdge(std::int64_t from, std::int64_t to, const Pose& T_a_b, const Matrix6d& information,
               EdgeKind kind);

  bool HasNode(std::int64_t id) const { return index_.count(id) != 0; }
  /// Node with `id`; CheckError when absent.
  const PoseGraphNode& node(std::int64_t id) const;
  PoseGraphNode& node(std::int64_t id);

  const std::vector<PoseGraphNode>& nodes() const { return nodes_; }
  std::vector<PoseGraphNode>& nodes() { return nodes_; }
  const std::vector<PoseGraphEdge>& edges() const { return edges_; }
  std::vector<PoseGraphEdge>& edges() { return edges_; }

  std::size_t NumLoopClosures() const;

 private:
  std::vector<PoseGraphNode> nodes_;
  std::vector<PoseGraphEdge> edges_;
  std::unordered_map<std::int64_t, std::size_t> index_;
};

/// Optimiser settings (YAML section "pose_graph").
struct PoseGraphConfig {
  int max_iterations =
      200;  ///< [iterations] Levenberg-Marquardt steps at most (Ceres' example: 200)
  double function_tolerance = 1e-6;  ///< [relative] stop when the cost changes less (Ceres default)
  double gradient_tolerance = 1e-10;  ///< [relative] Ceres default
  double parameter_tolerance = 1e-8;  ///< [relative] Ceres default
  /// Robust loss on loop-closure edges only ("none", "huber", "cauchy"); odometry stays quadratic.
  std::string loop_closure_loss = "huber";
  /// [whitened residual units] loss scale a: quadratic while |r| < a. sqrt(12.59) = 3.55 is the 95%
  /// quantile of a chi-square with 6 degrees of freedom, i.e. an inlier's |r|.
  double loop_closure_loss_scale = 3.55;
  int num_threads = 1;  ///< [threads] Jacobian evaluation threads

  /// Problems with the values, empty when fine.
  std::vector<std::string> Validate() const;
};

/// What the optimiser did. Expected conditions (no edges, no convergence) are flags, not errors.
struct PoseGraphResult {
  double initial_cost = 0.0;  ///< 0.5 sum rho(|r|^2) before, Ceres' convention
  double final_cost = 0.0;    ///< same, after
  /// Ceres' "Minimizer iterations" (successful + unsuccessful steps, counting the initial
  /// evaluation as one, so max_iterations = 5 can report 6).
  int iterations = 0;
  bool converged = false;     ///< Ceres reported CONVERGENCE (a tolerance was met)
  bool usable = false;        ///< the poses were updated with a usable solution
  double time_seconds = 0.0;  ///< Ceres' total time
  std::string termination;    ///< CONVERGENCE, NO_CONVERGENCE, FAILURE, ...
  std::string message;        ///< Ceres' explanation
  std::size_t num_nodes = 0;
  std::size_t num_edges = 0;
  std::size_t num_fixed = 0;  ///< nodes held constant (the FIX ones, else the first node)
};

/// One node's measurement of a plane landmark: the plane n.x = d in the node's frame.
struct PlaneLandmarkObservation {
  std::int64_t node = 0;
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  ///< unit, node frame
  double d = 0.0;                                     ///< [m]
  double normal_sigma = 0.01;                         ///< [rad] per tangent direction
  double offset_sigma = 0.01;                         ///< [m]
};

/// A plane of the world seen from several nodes; optimised together with the poses.
struct PlaneLandmark {
  Eigen::Vector3d normal =
      Eigen::Vector3d::UnitZ();  ///< unit, world frame (initial value / result)
  double d = 0.0;                ///< [m]
  std::vector<PlaneLandmarkObservation> observations;
};

/// Optimises the poses of `graph` in place. Nodes flagged `fixed` are held constant; when none is,
/// the first node is (removes the gauge freedom). Quaternions are normalised before optimising and
/// written back normalised. Throws CheckError when `config` is invalid. Prints nothing.
/// With `planes`, each landmark's observations add residuals (predicted minus measured normal and
/// offset in the node's frame, whitened by their sigmas, under the loop-closure loss) and the
/// landmarks are optimised too (written back); observations of unknown nodes are ignored.
PoseGraphResult OptimizePoseGraph(PoseGraph& graph, const PoseGraphConfig& config = {},
                                  std::vector<PlaneLandmark>* planes = nullptr);

/// Same, optimising only the nodes in `free_nodes` (all when null) with the others held: edges
/// between held nodes and held nodes' plane observations are left out, and a landmark seen from a
/// held node is held at its value. The cost of a window is then bounded by the window, not by the
/// graph.
PoseGraphResult OptimizePoseGraphWindow(PoseGraph& graph,
                                        const std::unordered_set<std::int64_t>* free_nodes,
                                        const PoseGraphConfig& config,
                                        std::vector<PlaneLandmark>* planes = nullptr);

/// 0.5 sum rho(|r|^2) of the graph as it is (same cost as the optimiser's).
double PoseGraphCost(const PoseGraph& graph, const PoseGraphConfig& config = {});

/// Residual and Jacobians of one edge's Ceres cost function, for tests and diagnostics. The pose
/// parameters are in Ceres' ambient layout x = (p_x, p_y, p_z, q_x, q_y, q_z, q_w), used as given
/// (not normalised). d_a, d_b: d residual / d x_a, d x_b.
struct EdgeResidualEvaluation {
  Vector6d residual = Vector6d::Zero();
  Eigen::Matrix<double, 6, 7> d_a = Eigen::Matrix<double, 6, 7>::Zero();
  Eigen::Matrix<double, 6, 7> d_b = Eigen::Matrix<double, 6, 7>::Zero();
};
EdgeResidualEvaluation EvaluateEdgeResidual(const PoseGraphEdge& edge,
                                            const Eigen::Matrix<double, 7, 1>& x_a,
                                            const Eigen::Matrix<double, 7, 1>& x_b);

/// Ambient parameters (p, q as x y z w) of a pose.
Eigen::Matrix<double, 7, 1> ToAmbient(const Pose& T);

}  // namespace planeslam::mapping
