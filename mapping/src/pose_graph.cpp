// Pose graph optimisation on Ceres (after Ceres' examples/slam/pose_graph_3d).
#include "planeslam/mapping/pose_graph.hpp"

#include <ceres/ceres.h>
#include <ceres/product_manifold.h>
#include <ceres/sphere_manifold.h>

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <map>
#include <memory>
#include <unordered_set>

#include "planeslam/datasets/errors.hpp"

namespace planeslam::mapping {

Pose PoseGraphNode::T_world_node() const {
  Pose T = Pose::Identity();
  T.linear() = rotation.normalized().toRotationMatrix();
  T.translation() = position;
  return T;
}

void PoseGraphNode::SetPose(const Pose& T_world_node) {
  position = T_world_node.translation();
  rotation = Eigen::Quaterniond(T_world_node.rotation()).normalized();
}

Pose PoseGraphEdge::T_a_b() const {
  Pose T = Pose::Identity();
  T.linear() = rotation.normalized().toRotationMatrix();
  T.translation() = translation;
  return T;
}

void PoseGraphEdge::SetMeasurement(const Pose& T_a_b) {
  translation = T_a_b.translation();
  rotation = Eigen::Quaterniond(T_a_b.rotation()).normalized();
}

void PoseGraph::AddNode(std::int64_t id, const Pose& T_world_node, bool fixed) {
  PoseGraphNode node;
  node.id = id;
  node.SetPose(T_world_node);
  node.fixed = fixed;
  AddNode(node);
}

void PoseGraph::AddNode(const PoseGraphNode& node) {
  PLANESLAM_CHECK(!HasNode(node.id), "duplicate pose graph node id " << node.id);
  index_.emplace(node.id, nodes_.size());
  nodes_.push_back(node);
}

void PoseGraph::AddEdge(const PoseGraphEdge& edge) {
  PLANESLAM_CHECK(HasNode(edge.from), "edge from unknown node " << edge.from);
  PLANESLAM_CHECK(HasNode(edge.to), "edge to unknown node " << edge.to);
  PLANESLAM_CHECK(edge.information.allFinite() &&
                      (edge.information - edge.information.transpose()).cwiseAbs().maxCoeff() <=
                          1e-9 * edge.information.cwiseAbs().maxCoeff(),
                  "edge " << edge.from << "->" << edge.to << ": information not symmetric");
  const Eigen::LLT<Matrix6d> llt(edge.information);
  PLANESLAM_CHECK(llt.info() == Eigen::Success && Matrix6d(llt.matrixL()).allFinite(),
                  "edge " << edge.from << "->" << edge.to << ": information not positive definite");
  edges_.push_back(edge);
}

void PoseGraph::AddEdge(std::int64_t from, std::int64_t to, const Pose& T_a_b,
                        const Matrix6d& information, EdgeKind kind) {
  PoseGraphEdge edge;
  edge.from = from;
  edge.to = to;
  edge.SetMeasurement(T_a_b);
  edge.information = information;
  edge.kind = kind;
  AddEdge(edge);
}

const PoseGraphNode& PoseGraph::node(std::int64_t id) const {
  auto it = index_.find(id);
  PLANESLAM_CHECK(it != index_.end(), "no pose graph node " << id);
  return nodes_[it->second];
}

PoseGraphNode& PoseGraph::node(std::int64_t id) {
  auto it = index_.find(id);
  PLANESLAM_CHECK(it != index_.end(), "no pose graph node " << id);
  return nodes_[it->second];
}

std::size_t PoseGraph::NumLoopClosures() const {
  return static_cast<std::size_t>(std::count_if(edges_.begin(), edges_.end(), [](const auto& e) {
    return e.kind == EdgeKind::kLoopClosure;
  }));
}

std::vector<std::string> PoseGraphConfig::Validate() const {
  std::vector<std::string> problems;
  if (max_iterations < 0) problems.push_back("max_iterations must be >= 0");
  if (!(function_tolerance >= 0) || !(gradient_tolerance >= 0) || !(parameter_tolerance >= 0)) {
    problems.push_back("tolerances must be >= 0");
  }
  if (loop_closure_loss != "none" && loop_closure_loss != "huber" &&
      loop_closure_loss != "cauchy") {
    problems.push_back("loop_closure_loss must be none, huber or cauchy, not '" +
                       loop_closure_loss + "'");
  }
  if (!(loop_closure_loss_scale > 0) || !std::isfinite(loop_closure_loss_scale)) {
    problems.push_back("loop_closure_loss_scale must be > 0");
  }
  if (num_threads < 1) problems.push_back("num_threads must be >= 1");
  return problems;
}

Eigen::Matrix<double, 7, 1> ToAmbient(const Pose& T) {
  Eigen::Matrix<double, 7, 1> x;
  const Eigen::Quaterniond q(T.rotation());
  x << T.translation(), q.x(), q.y(), q.z(), q.w();
  return x;
}

namespace {

/// Edge residual of the file comment in pose_graph.hpp. Parameters: p_a (3), q_a (4, Eigen's
/// x y z w memory order), p_b, q_b.
class RelativePoseError {
 public:
  RelativePoseError(const Eigen::Vector3d& p_ab, const Eigen::Quaterniond& q_ab,
                    const Matrix6d& sqrt_information)
      : p_ab_(p_ab), q_ab_(q_ab), sqrt_information_(sqrt_information) {}

  template <typename T>
  bool operator()(const T* p_a_ptr, const T* q_a_ptr, const T* p_b_ptr, const T* q_b_ptr,
                  T* residuals_ptr) const {
    Eigen::Map<const Eigen::Matrix<T, 3, 1>> p_a(p_a_ptr);
    Eigen::Map<const Eigen::Quaternion<T>> q_a(q_a_ptr);
    Eigen::Map<const Eigen::Matrix<T, 3, 1>> p_b(p_b_ptr);
    Eigen::Map<const Eigen::Quaternion<T>> q_b(q_b_ptr);

    // Estimated relative pose; conjugate == inverse on the unit quaternions the manifold keeps.
    const Eigen::Quaternion<T> q_a_inverse = q_a.conjugate();
    const Eigen::Quaternion<T> q_ab_estimated = q_a_inverse * q_b;
    const Eigen::Matrix<T, 3, 1> p_ab_estimated = q_a_inverse * (p_b - p_a);
    const Eigen::Quaternion<T> delta_q = q_ab_.template cast<T>() * q_ab_estimated.conjugate();

    Eigen::Map<Eigen::Matrix<T, 6, 1>> residuals(residuals_ptr);
    residuals.template head<3>() = p_ab_estimated - p_ab_.template cast<T>();
    // 2 vec(dq) ~ rotation vector of dq for small errors, so rotation information is per rad^2.
    residuals.template tail<3>() = T(2.0) * delta_q.vec();
    residuals.applyOnTheLeft(sqrt_information_.template cast<T>());
    return true;
  }

  const Eigen::Vector3d& p_ab() const { return p_ab_; }
  const Eigen::Quaterniond& q_ab() const { return q_ab_; }
  const Matrix6d& sqrt_information() const { return sqrt_information_; }

 private:
  Eigen::Vector3d p_ab_;
  Eigen::Quaterniond q_ab_;
  Matrix6d sqrt_information_;
};

/// 4x4 matrices of quaternion products in Eigen's (x y z w) order: a * b = Left(a) b = Right(b) a.
Eigen::Matrix4d QuaternionLeft(const Eigen::Quaterniond& a) {
  const double x = a.x(), y = a.y(), z = a.z(), w = a.w();
  Eigen::Matrix4d m;
  m << w, -z, y, x,  //
      z, w, -x, y,   //
      -y, x, w, z,   //
      -x, -y, -z, w;
  return m;
}

Eigen::Matrix4d QuaternionRight(const Eigen::Quaterniond& b) {
  const double x = b.x(), y = b.y(), z = b.z(), w = b.w();
  Eigen::Matrix4d m;
  m << w, z, -y, x,  //
      -z, w, x, y,   //
      y, -x, w, z,   //
      -x, -y, -z, w;
  return m;
}

Eigen::Matrix3d Skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0.0, -v.z(), v.y(),  //
      v.z(), 0.0, -v.x(),   //
      -v.y(), v.x(), 0.0;
  return m;
}

/// RelativePoseError with analytic Jacobians (the pose graph's hot loop). The residual is
/// evaluated by the same code as the automatic version; the Jacobians are its exact derivatives
/// in the ambient quaternion coordinates:
///   rotation: dq = q_ab * conj(q_b) * q_a is bilinear, d dq/d q_a = Left(q_ab * conj(q_b)),
///             d dq/d q_b = Left(q_ab) Right(q_a) diag(-1, -1, -1, 1);
///   position: with u = vec(q_a), w = q_a.w, t = p_b - p_a, Eigen rotates by conj(q_a) as
///             f = t - 2w (u x t) + 2 u x (u x t), so df/dt = I - 2w [u]x + 2 [u]x^2,
///             df/dw = -2 (u x t), df/du = 2w [t]x + 2 ((u.t) I + u t^T - 2 t u^T).
///
/// Each pose is one 7-parameter block (p, then q): the normal equations then have one 6x6 block
/// per pair of joined poses instead of four smaller ones, which the sparse Cholesky
/// factorisation and the Jacobian products handle with less overhead.
class RelativePoseCost final : public ceres::SizedCostFunction<6, 7, 7> {
 public:
  explicit RelativePoseCost(const RelativePoseError& error) : error_(error) {}

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const double* x_a = parameters[0];
    const double* x_b = parameters[1];
    error_(x_a, x_a + 3, x_b, x_b + 3, residuals);
    if (jacobians == nullptr) return true;
    using RowMajor67 = Eigen::Matrix<double, 6, 7, Eigen::RowMajor>;
    const Matrix6d& U = error_.sqrt_information();
    const Eigen::Map<const Eigen::Vector3d> p_a(x_a);
    const Eigen::Map<const Eigen::Quaterniond> q_a(x_a + 3);
    const Eigen::Map<const Eigen::Vector3d> p_b(x_b);
    const Eigen::Map<const Eigen::Quaterniond> q_b(x_b + 3);
    const Eigen::Vector3d u = q_a.vec();
    const double w = q_a.w();
    const Eigen::Vector3d t = p_b - p_a;
    const Eigen::Matrix3d su = Skew(u);
    const Eigen::Matrix3d dt = Eigen::Matrix3d::Identity() - 2.0 * w * su + 2.0 * su * su;
    if (jacobians[0] != nullptr) {
      Eigen::Map<RowMajor67> j(jacobians[0]);
      j.leftCols<3>() = -U.leftCols<3>() * dt;
      Eigen::Matrix<double, 6, 4> e;
      e.topLeftCorner<3, 3>() = 2.0 * w * Skew(t) + 2.0 * (u.dot(t) * Eigen::Matrix3d::Identity() +
                                                           u * t.transpose() - 2.0 * t * u.transpose());
      e.topRightCorner<3, 1>() = -2.0 * u.cross(t);
      const Eigen::Quaterniond q_ab_qb_inv = error_.q_ab() * q_b.conjugate();
      e.bottomRows<3>() = 2.0 * QuaternionLeft(q_ab_qb_inv).topRows<3>();
      j.rightCols<4>() = U * e;
    }
    if (jacobians[1] != nullptr) {
      Eigen::Map<RowMajor67> j(jacobians[1]);
      j.leftCols<3>() = U.leftCols<3>() * dt;
      Eigen::Matrix4d m = QuaternionLeft(error_.q_ab()) * QuaternionRight(q_a);
      m.leftCols<3>() = -m.leftCols<3>();
      j.rightCols<4>() = U.rightCols<3>() * (2.0 * m.topRows<3>());
    }
    return true;
  }

  static ceres::CostFunction* Create(const PoseGraphEdge& edge) {
    // Upper factor U = L^T so that |U e|^2 = e^T L L^T e = e^T information e.
    const Matrix6d sqrt_information = edge.information.llt().matrixU();
    const RelativePoseError error(edge.translation, edge.rotation.normalized(), sqrt_information);
    return new RelativePoseCost(error);
  }

 private:
  RelativePoseError error_;
};

/// A node's observation of a plane landmark: residual (R^T n_w - n_obs) / sigma_n (3, of which
/// two count: both normals are unit) and (d_w - n_w.p - d_obs) / sigma_d, with the node pose
/// (p, q) = T_world_node and the landmark (n_w, d_w) in the world.
class PlaneObservationError {
 public:
  explicit PlaneObservationError(const PlaneLandmarkObservation& obs) : obs_(obs) {}

  template <typename T>
  bool operator()(const T* pose_ptr, const T* n_ptr, const T* d_ptr, T* residual_ptr) const {
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> p(pose_ptr);
    const Eigen::Map<const Eigen::Quaternion<T>> q(pose_ptr + 3);
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> n(n_ptr);
    const Eigen::Matrix<T, 3, 1> n_node = q.conjugate() * n;
    const T d_node = d_ptr[0] - n.dot(p);
    for (int k = 0; k < 3; ++k) {
      residual_ptr[k] = (n_node[k] - T(obs_.normal[k])) / T(obs_.normal_sigma);
    }
    residual_ptr[3] = (d_node - T(obs_.d)) / T(obs_.offset_sigma);
    return true;
  }

  static ceres::CostFunction* Create(const PlaneLandmarkObservation& obs) {
    return new ceres::AutoDiffCostFunction<PlaneObservationError, 4, 7, 3, 1>(
        new PlaneObservationError(obs));
  }

 private:
  PlaneLandmarkObservation obs_;
};

/// A node's pose block: position (Euclidean) and unit quaternion (Eigen's x y z w order).
using PoseManifold =
    ceres::ProductManifold<ceres::EuclideanManifold<3>, ceres::EigenQuaternionManifold>;

ceres::LossFunction* MakeLoopClosureLoss(const PoseGraphConfig& config) {
  // Ceres' losses act on s = |r|^2 with scale a: quadratic for s < a^2.
  if (config.loop_closure_loss == "huber")
    return new ceres::HuberLoss(config.loop_closure_loss_scale);
  if (config.loop_closure_loss == "cauchy") {
    return new ceres::CauchyLoss(config.loop_closure_loss_scale);
  }
  return nullptr;
}

const char* TerminationName(ceres::TerminationType type) {
  switch (type) {
    case ceres::CONVERGENCE:
      return "CONVERGENCE";
    case ceres::NO_CONVERGENCE:
      return "NO_CONVERGENCE";
    case ceres::FAILURE:
      return "FAILURE";
    case ceres::USER_SUCCESS:
      return "USER_SUCCESS";
    case ceres::USER_FAILURE:
      return "USER_FAILURE";
  }
  return "UNKNOWN";
}

/// One parameter block per node (p, then q in Eigen's x y z w order) plus the problem with one
/// residual block per edge.
struct BuiltProblem {
  std::vector<Eigen::Matrix<double, 7, 1>> poses;
  std::unique_ptr<ceres::Problem> problem;
  std::size_t num_fixed = 0;
};

/// With `free_nodes`, only those nodes are optimised: edges between held nodes are left out, as
/// are held nodes' plane observations, and a landmark seen from a held node is held too (its
/// value rests on observations outside the window).
BuiltProblem BuildProblem(const PoseGraph& graph, const PoseGraphConfig& config,
                          std::vector<PlaneLandmark>* planes = nullptr,
                          const std::unordered_set<std::int64_t>* free_nodes = nullptr) {
  BuiltProblem built;
  const auto& nodes = graph.nodes();
  built.poses.resize(nodes.size());
  std::unordered_map<std::int64_t, std::size_t> index;
  for (std::size_t i = 0; i < nodes.size(); ++i) {
    built.poses[i] << nodes[i].position, nodes[i].rotation.normalized().coeffs();
    index.emplace(nodes[i].id, i);
  }

  ceres::Problem::Options problem_options;
  // One loss object shared by all loop closures; the problem owns and deletes it once.
  problem_options.loss_function_ownership = ceres::TAKE_OWNERSHIP;
  built.problem = std::make_unique<ceres::Problem>(problem_options);
  ceres::Problem& problem = *built.problem;
  ceres::LossFunction* loop_loss = MakeLoopClosureLoss(config);
  bool loss_used = false;
  const auto is_free = [&](std::int64_t id) { return !free_nodes || free_nodes->count(id) != 0; };
  for (const auto& edge : graph.edges()) {
    if (!is_free(edge.from) && !is_free(edge.to)) continue;
    const std::size_t a = index.at(edge.from);
    const std::size_t b = index.at(edge.to);
    ceres::LossFunction* loss = edge.kind == EdgeKind::kLoopClosure ? loop_loss : nullptr;
    loss_used |= loss != nullptr;
    problem.AddResidualBlock(RelativePoseCost::Create(edge), loss, built.poses[a].data(),
                             built.poses[b].data());
  }
  if (planes) {
    for (PlaneLandmark& plane : *planes) {
      plane.normal.normalize();
      const bool held = std::any_of(plane.observations.begin(), plane.observations.end(),
                                    [&](const auto& obs) { return !is_free(obs.node); });
      int used = 0;
      for (const PlaneLandmarkObservation& obs : plane.observations) {
        const auto it = index.find(obs.node);
        if (it == index.end() || !is_free(obs.node)) continue;
        const std::size_t a = it->second;
        problem.AddResidualBlock(PlaneObservationError::Create(obs), loop_loss,
                                 built.poses[a].data(), plane.normal.data(), &plane.d);
        loss_used |= loop_loss != nullptr;
        ++used;
      }
      if (used > 0 && held) {
        problem.SetParameterBlockConstant(plane.normal.data());
        problem.SetParameterBlockConstant(&plane.d);
      } else if (used > 0) {
        problem.SetManifold(plane.normal.data(), new ceres::SphereManifold<3>);
      }
    }
  }
  if (!loss_used) delete loop_loss;

  for (std::size_t i = 0; i < nodes.size(); ++i) {
    if (!problem.HasParameterBlock(built.poses[i].data())) {
      // An isolated node: nothing constrains it, leave it out of the problem.
      continue;
    }
    problem.SetManifold(built.poses[i].data(), new PoseManifold);
  }
  // Gauge: the FIX nodes, else the first node (as g2o does).
  std::vector<std::size_t> fixed;
  for (std::size_t i = 0; i < nodes.size(); ++i) {
    if (nodes[i].fixed || !is_free(nodes[i].id)) fixed.push_back(i);
  }
  if (fixed.empty() && !nodes.empty()) fixed.push_back(0);
  for (std::size_t i : fixed) {
    if (!problem.HasParameterBlock(built.poses[i].data())) continue;
    problem.SetParameterBlockConstant(built.poses[i].data());
  }
  built.num_fixed = fixed.size();
  return built;
}

}  // namespace

PoseGraphResult OptimizePoseGraph(PoseGraph& graph, const PoseGraphConfig& config,
                                  std::vector<PlaneLandmark>* planes) {
  return OptimizePoseGraphWindow(graph, nullptr, config, planes);
}

PoseGraphResult OptimizePoseGraphWindow(PoseGraph& graph,
                                        const std::unordered_set<std::int64_t>* free_nodes,
                                        const PoseGraphConfig& config,
                                        std::vector<PlaneLandmark>* planes) {
  const auto problems = config.Validate();
  PLANESLAM_CHECK(problems.empty(), "invalid PoseGraphConfig: " << problems.front());
  PoseGraphResult result;
  result.num_nodes = graph.nodes().size();
  result.num_edges = graph.edges().size();
  // Landmarks are optimised in a copy, written back only with a usable solution.
  std::vector<PlaneLandmark> landmarks = planes ? *planes : std::vector<PlaneLandmark>();
  BuiltProblem built = BuildProblem(graph, config, planes ? &landmarks : nullptr, free_nodes);
  result.num_fixed = built.num_fixed;
  if (graph.edges().empty()) {
    result.converged = true;
    result.usable = true;
    result.termination = "CONVERGENCE";
    result.message = "no edges: nothing to optimise";
    return result;
  }

  ceres::Solver::Options options;
  options.minimizer_type = ceres::TRUST_REGION;
  options.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
  options.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  // Eigen's simplicial LDLT on Ceres' block AMD ordering: the normal equations of a pose graph are
  // thin (6x6 blocks, a few per row), where CHOLMOD's supernodes and the BLAS calls behind them
  // cost more than they save; the steps agree to rounding.
  if (ceres::IsSparseLinearAlgebraLibraryTypeAvailable(ceres::EIGEN_SPARSE)) {
    options.sparse_linear_algebra_library_type = ceres::EIGEN_SPARSE;
  }
  options.max_num_iterations = config.max_iterations;
  options.function_tolerance = config.function_tolerance;
  options.gradient_tolerance = config.gradient_tolerance;
  options.parameter_tolerance = config.parameter_tolerance;
  options.num_threads = config.num_threads;
  // Core libraries print nothing; reporting is the apps' business.
  options.logging_type = ceres::SILENT;
  options.minimizer_progress_to_stdout = false;

  ceres::Solver::Summary summary;
  ceres::Solve(options, built.problem.get(), &summary);

  result.initial_cost = summary.initial_cost;
  result.final_cost = summary.final_cost;
  result.iterations = summary.num_successful_steps + summary.num_unsuccessful_steps;
  result.converged = summary.termination_type == ceres::CONVERGENCE;
  result.usable = summary.IsSolutionUsable();
  result.time_seconds = summary.total_time_in_seconds;
  result.termination = TerminationName(summary.termination_type);
  result.message = summary.message;

  if (result.usable) {
    auto& nodes = graph.nodes();
    for (std::size_t i = 0; i < nodes.size(); ++i) {
      nodes[i].position = built.poses[i].head<3>();
      nodes[i].rotation = Eigen::Quaterniond(built.poses[i].tail<4>()).normalized();
    }
    if (planes) *planes = std::move(landmarks);
  }
  return result;
}

double PoseGraphCost(const PoseGraph& graph, const PoseGraphConfig& config) {
  const auto problems = config.Validate();
  PLANESLAM_CHECK(problems.empty(), "invalid PoseGraphConfig: " << problems.front());
  if (graph.edges().empty()) return 0.0;
  BuiltProblem built = BuildProblem(graph, config);
  double cost = 0.0;
  built.problem->Evaluate(ceres::Problem::EvaluateOptions(), &cost, nullptr, nullptr, nullptr);
  return cost;
}

EdgeResidualEvaluation EvaluateEdgeResidual(const PoseGraphEdge& edge,
                                            const Eigen::Matrix<double, 7, 1>& x_a,
                                            const Eigen::Matrix<double, 7, 1>& x_b) {
  std::unique_ptr<ceres::CostFunction> cost(RelativePoseCost::Create(edge));
  const Eigen::Matrix<double, 7, 1> a = x_a;
  const Eigen::Matrix<double, 7, 1> b = x_b;
  const double* parameters[2] = {a.data(), b.data()};
  // Ceres wants row-major Jacobians, one per parameter block.
  Eigen::Matrix<double, 6, 7, Eigen::RowMajor> j_a, j_b;
  double* jacobians[2] = {j_a.data(), j_b.data()};
  EdgeResidualEvaluation out;
  cost->Evaluate(parameters, out.residual.data(), jacobians);
  out.d_a = j_a;
  out.d_b = j_b;
  return out;
}

}  // namespace planeslam::mapping
