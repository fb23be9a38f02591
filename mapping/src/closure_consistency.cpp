#include "planeslam/mapping/closure_consistency.hpp"

#include <Eigen/Cholesky>
#include <algorithm>
#include <functional>
#include <limits>
#include <queue>

#include "planeslam/registration/geometry.hpp"

namespace planeslam::mapping {
namespace {

using registration::Skew;

Matrix6d SymmetricInverse(const Matrix6d& m) {
  const Matrix6d symmetric = 0.5 * (m + m.transpose());
  Matrix6d inverse = symmetric.ldlt().solve(Matrix6d::Identity());
  return 0.5 * (inverse + inverse.transpose());
}

}  // namespace

UncertainPose Compose(const UncertainPose& a, const UncertainPose& b) {
  const Eigen::Matrix3d R_a = a.T.linear();
  Matrix6d J_a = Matrix6d::Identity();
  J_a.topRightCorner<3, 3>() = -Skew(R_a * b.T.translation());
  Matrix6d J_b = Matrix6d::Zero();
  J_b.topLeftCorner<3, 3>() = R_a;
  J_b.bottomRightCorner<3, 3>() = R_a;
  UncertainPose c;
  c.T = a.T * b.T;
  c.covariance = J_a * a.covariance * J_a.transpose() + J_b * b.covariance * J_b.transpose();
  return c;
}

UncertainPose Invert(const UncertainPose& x) {
  const Eigen::Matrix3d Rt = x.T.linear().transpose();
  Matrix6d J = Matrix6d::Zero();
  J.topLeftCorner<3, 3>() = -Rt;
  J.topRightCorner<3, 3>() = -Rt * Skew(x.T.translation());
  J.bottomRightCorner<3, 3>() = -Rt;
  UncertainPose inverse;
  inverse.T = x.T.inverse();
  inverse.covariance = J * x.covariance * J.transpose();
  return inverse;
}

double IdentityChi2(const UncertainPose& x) {
  const Vector6d e = registration::BoxMinus(x.T, Pose::Identity());
  const double chi2 = e.dot(SymmetricInverse(x.covariance) * e);
  return std::isfinite(chi2) ? chi2 : std::numeric_limits<double>::infinity();
}

GraphPaths::GraphPaths(const PoseGraph& graph, std::size_t max_nodes)
    : graph_(graph), max_nodes_(max_nodes) {
  for (const PoseGraphEdge& edge : graph.edges()) AddEdge(edge);
}

int GraphPaths::Number(std::int64_t id) {
  const auto [it, added] = number_.try_emplace(id, static_cast<int>(ids_.size()));
  if (added) {
    ids_.push_back(id);
    links_.emplace_back();
    reached_.emplace_back();
  }
  return it->second;
}

int GraphPaths::Find(std::int64_t id) const {
  const auto it = number_.find(id);
  return it == number_.end() ? -1 : it->second;
}

void GraphPaths::AddEdge(const PoseGraphEdge& edge) {
  const UncertainPose forward{edge.T_a_b(), SymmetricInverse(edge.information)};
  const UncertainPose backward = Invert(forward);
  const int from = Number(edge.from), to = Number(edge.to);
  const int forward_index = static_cast<int>(covariances_.size());
  covariances_.push_back(forward.covariance);
  covariances_.push_back(backward.covariance);
  links_[to].push_back({from, forward_index, forward.covariance.trace()});
  links_[from].push_back({to, forward_index + 1, backward.covariance.trace()});
}

void GraphPaths::RemoveEdge(std::int64_t from, std::int64_t to) {
  const auto erase_one = [&](int a, int b) {
    if (a < 0 || b < 0) return;
    std::vector<Link>& links = links_[static_cast<std::size_t>(a)];
    const auto it =
        std::find_if(links.begin(), links.end(), [&](const Link& l) { return l.to == b; });
    if (it != links.end()) links.erase(it);
  };
  erase_one(Find(from), Find(to));
  erase_one(Find(to), Find(from));
}

std::optional<UncertainPose> GraphPaths::Relative(std::int64_t from, std::int64_t to) {
  return RelativeFrom({from}, to).front();
}

void GraphPaths::SearchBack(int target, std::size_t wanted) {
  reached_[target] = {search_, false, false, 0.0, -1, -1};
  queue_.clear();
  queue_.push_back({0.0, ids_[target], target});
  const std::greater<Queued> later;
  std::size_t settled = 0, found = 0;
  while (!queue_.empty() && found < wanted && settled < max_nodes_) {
    std::pop_heap(queue_.begin(), queue_.end(), later);
    const Queued top = queue_.back();
    queue_.pop_back();
    Reached& r = reached_[top.node];
    if (r.settled || top.distance > r.distance) continue;
    r.settled = true;
    found += r.wanted ? 1 : 0;
    ++settled;
    for (const Link& link : links_[top.node]) {
      const double d = top.distance + link.weight;
      Reached& other = reached_[link.to];
      if (other.stamp != search_) {
        other = {search_, false, false, d, top.node, link.covariance};
      } else if (!other.settled && d < other.distance) {
        other.distance = d;
        other.next = top.node;
        other.covariance = link.covariance;
      } else {
        continue;
      }
      queue_.push_back({d, ids_[link.to], link.to});
      std::push_heap(queue_.begin(), queue_.end(), later);
    }
  }
}

std::vector<std::optional<UncertainPose>> GraphPaths::RelativeFrom(
    const std::vector<std::int64_t>& sources, std::int64_t to) {
  std::vector<std::optional<UncertainPose>> paths(sources.size());
  const int target = Find(to);
  if (++search_ == 0) {  // the stamps wrapped around
    for (Reached& r : reached_) r.stamp = 0;
    search_ = 1;
  }
  // Dijkstra on the covariance trace, from the target back to every source (a node without
  // edges reaches nothing); each path found is then composed with the current poses.
  std::vector<int> numbers(sources.size(), -1);  // -1: the target itself, or unreachable
  std::size_t wanted = 0;
  for (std::size_t k = 0; k < sources.size(); ++k) {
    numbers[k] = sources[k] == to || target < 0 ? -1 : Find(sources[k]);
    const int source = numbers[k];
    if (source < 0 || reached_[source].stamp == search_) continue;
    reached_[source] = {search_, false, true, std::numeric_limits<double>::infinity(), -1, -1};
    ++wanted;
  }
  if (wanted > 0) SearchBack(target, wanted);
  for (std::size_t k = 0; k < sources.size(); ++k) {
    if (sources[k] == to) {
      paths[k] = UncertainPose{};
      continue;
    }
    const int source = numbers[k];
    if (source < 0 || !reached_[source].settled) continue;
    UncertainPose path;
    for (int node = source; node != target; node = reached_[node].next) {
      const int next = reached_[node].next;
      UncertainPose step;
      step.T =
          graph_.node(ids_[node]).T_world_node().inverse() * graph_.node(ids_[next]).T_world_node();
      step.covariance = covariances_[static_cast<std::size_t>(reached_[node].covariance)];
      path = Compose(path, step);
    }
    paths[k] = path;
  }
  return paths;
}

namespace {

/// Tomita-Seki style branch and bound: candidates ordered by a greedy colouring, whose colour
/// number bounds the clique any prefix can still give.
class CliqueSearch {
 public:
  explicit CliqueSearch(const std::vector<std::vector<bool>>& adjacent) : adjacent_(adjacent) {}

  std::vector<int> Run() {
    std::vector<int> all(adjacent_.size());
    for (std::size_t i = 0; i < all.size(); ++i) all[i] = static_cast<int>(i);
    std::vector<int> current;
    Expand(current, all);
    std::sort(best_.begin(), best_.end());
    return best_;
  }

 private:
  void Colour(const std::vector<int>& candidates, std::vector<int>* order,
              std::vector<int>* bounds) const {
    std::vector<std::vector<int>> classes;
    for (int v : candidates) {
      std::size_t k = 0;
      for (; k < classes.size(); ++k) {
        const bool free = std::none_of(classes[k].begin(), classes[k].end(),
                                       [&](int u) { return adjacent_[v][u]; });
        if (free) break;
      }
      if (k == classes.size()) classes.emplace_back();
      classes[k].push_back(v);
    }
    for (std::size_t k = 0; k < classes.size(); ++k) {
      for (int v : classes[k]) {
        order->push_back(v);
        bounds->push_back(static_cast<int>(k) + 1);
      }
    }
  }

  void Expand(std::vector<int>& current, const std::vector<int>& candidates) {
    std::vector<int> order, bounds;
    Colour(candidates, &order, &bounds);
    for (int k = static_cast<int>(order.size()) - 1; k >= 0; --k) {
      if (current.size() + static_cast<std::size_t>(bounds[k]) <= best_.size()) return;
      const int v = order[k];
      current.push_back(v);
      std::vector<int> next;
      for (int i = 0; i < k; ++i) {
        if (adjacent_[v][order[i]]) next.push_back(order[i]);
      }
      if (next.empty()) {
        if (current.size() > best_.size()) best_ = current;
      } else {
        Expand(current, next);
      }
      current.pop_back();
    }
  }

  const std::vector<std::vector<bool>>& adjacent_;
  std::vector<int> best_;
};

}  // namespace

std::vector<int> MaximumClique(const std::vector<std::vector<bool>>& adjacent) {
  return CliqueSearch(adjacent).Run();
}

}  // namespace planeslam::mapping
