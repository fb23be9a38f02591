#include "planeslam/registration/plane_association.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <map>
#include <numeric>
#include <optional>
#include <tuple>

#include "plane_residual.hpp"
#include "planeslam/datasets/errors.hpp"
#include "prior_step.hpp"

namespace planeslam::registration {

std::vector<std::string> AssociationConfig::Validate() const {
  std::vector<std::string> p;
  if (!(max_normal_angle_deg > 0 && max_normal_angle_deg <= 180))
    p.push_back("max_normal_angle_deg must be in (0, 180]");
  if (!(max_offset_difference > 0)) p.push_back("max_offset_difference must be > 0");
  if (!(max_extent_ratio == 0 || max_extent_ratio >= 1))
    p.push_back("max_extent_ratio must be 0 (off) or >= 1");
  if (!(pair_angle_tolerance_deg > 0)) p.push_back("pair_angle_tolerance_deg must be > 0");
  if (!(parallel_angle_deg >= 0 && parallel_angle_deg < 90))
    p.push_back("parallel_angle_deg must be in [0, 90)");
  if (!(pair_offset_tolerance > 0)) p.push_back("pair_offset_tolerance must be > 0");
  if (!(flip_max_offset >= 0)) p.push_back("flip_max_offset must be >= 0");
  if (max_candidates_per_plane < 1) p.push_back("max_candidates_per_plane must be >= 1");
  if (max_tied_cliques < 1) p.push_back("max_tied_cliques must be >= 1");
  if (max_search_nodes < 1) p.push_back("max_search_nodes must be >= 1");
  if (!(inlier_chi2 > 0)) p.push_back("inlier_chi2 must be > 0");
  if (!(prior_gate_chi2 >= 0)) p.push_back("prior_gate_chi2 must be >= 0");
  return p;
}

namespace {

constexpr double kDeg = M_PI / 180.0;

struct PlaneInfo {
  bool ok = false;
  Eigen::Vector3d n = Eigen::Vector3d::UnitZ();
  double d = 0.0;
  double var_n = 0.0;   ///< per tangent axis [rad^2]
  double var_d = 0.0;   ///< [m^2]
  double extent = 0.0;  ///< sqrt(largest scatter eigenvalue / K) [m], 0 = unknown
};

PlaneInfo Info(const detection::Plane& p, const RegistrationConfig& rc) {
  PlaneInfo info;
  if (!p.normal.allFinite() || !std::isfinite(p.d) || p.normal.norm() < 0.5) return info;
  info.ok = true;
  info.n = p.normal.normalized();
  info.d = p.d;
  const Eigen::Matrix4d cov =
      PlaneCovarianceOrFallback(p, rc.fallback_point_sigma) * rc.covariance_scale;
  info.var_n = 0.5 * cov.topLeftCorner<3, 3>().trace() + rc.min_normal_sigma * rc.min_normal_sigma;
  info.var_d = cov(3, 3) + rc.min_offset_sigma * rc.min_offset_sigma;
  if (p.point_count > 0 && p.eigenvalues(2) > 0 && std::isfinite(p.eigenvalues(2))) {
    info.extent = std::sqrt(p.eigenvalues(2) / static_cast<double>(p.point_count));
  }
  return info;
}

struct Candidate {
  int i = 0;  ///< prev
  int j = 0;  ///< curr
  bool flip = false;
  Eigen::Vector3d n_b = Eigen::Vector3d::UnitZ();  ///< current normal, flipped if `flip`
  double d_b = 0.0;
  double score = 0.0;  ///< normalised gate distance, smaller is better
};

using Bits = std::vector<std::uint64_t>;

/// Maximum cliques of a small graph by branch and bound with a greedy-colouring bound (Tomita and
/// Seki's MCQ); collects up to `max_ties` cliques of the maximum size.
class CliqueSearch {
 public:
  CliqueSearch(const std::vector<Bits>& adj, int n, int max_ties, int max_nodes)
      : adj_(adj), n_(n), words_((n + 63) / 64), max_ties_(max_ties), max_nodes_(max_nodes) {}

  void Run() {
    Bits p(words_, 0);
    for (int v = 0; v < n_; ++v) p[v / 64] |= std::uint64_t{1} << (v % 64);
    std::vector<int> c;
    if (n_ > 0) Expand(&c, p);
  }
  const std::vector<std::vector<int>>& cliques() const { return cliques_; }
  bool exhausted() const { return exhausted_; }

 private:
  static bool Empty(const Bits& b) {
    for (auto w : b) {
      if (w) return false;
    }
    return true;
  }
  static int First(const Bits& b) {
    for (std::size_t k = 0; k < b.size(); ++k) {
      if (b[k]) return static_cast<int>(k * 64 + __builtin_ctzll(b[k]));
    }
    return -1;
  }
  static void Reset(Bits* b, int v) { (*b)[v / 64] &= ~(std::uint64_t{1} << (v % 64)); }

  void ColorSort(const Bits& p, std::vector<int>* order, std::vector<int>* colors) const {
    Bits u = p;
    int color = 0;
    while (!Empty(u)) {
      ++color;
      Bits q = u;
      while (!Empty(q)) {
        const int v = First(q);
        Reset(&q, v);
        Reset(&u, v);
        for (int k = 0; k < words_; ++k) q[k] &= ~adj_[v][k];
        order->push_back(v);
        colors->push_back(color);
      }
    }
  }

  void Record(const std::vector<int>& c) {
    const int size = static_cast<int>(c.size());
    if (size > best_) {
      best_ = size;
      cliques_.assign(1, c);
    } else if (size == best_ && static_cast<int>(cliques_.size()) < max_ties_) {
      cliques_.push_back(c);
    }
  }

  void Expand(std::vector<int>* c, Bits p) {
    if (++nodes_ > max_nodes_) {
      exhausted_ = true;
      return;
    }
    std::vector<int> order, colors;
    ColorSort(p, &order, &colors);
    for (int k = static_cast<int>(order.size()) - 1; k >= 0; --k) {
      // Equal-size cliques are still wanted for the tie-break until enough are collected.
      const bool ties_full = static_cast<int>(cliques_.size()) >= max_ties_;
      if (static_cast<int>(c->size()) + colors[k] < best_ + (ties_full ? 1 : 0)) return;
      const int v = order[k];
      c->push_back(v);
      Bits np(words_);
      for (int w = 0; w < words_; ++w) np[w] = p[w] & adj_[v][w];
      if (Empty(np)) {
        Record(*c);
      } else {
        Expand(c, np);
      }
      c->pop_back();
      Reset(&p, v);
      if (exhausted_) return;
    }
  }

  const std::vector<Bits>& adj_;
  int n_;
  int words_;
  int max_ties_;
  int max_nodes_;
  int nodes_ = 0;
  int best_ = 0;
  bool exhausted_ = false;
  std::vector<std::vector<int>> cliques_;
};

double LogDet(const Matrix6d& c) {
  Eigen::SelfAdjointEigenSolver<Matrix6d> es(c);
  double s = 0.0;
  for (int k = 0; k < 6; ++k) s += std::log(std::max(es.eigenvalues()(k), 1e-300));
  return s;
}

std::vector<PlaneInfo> Infos(const std::vector<detection::Plane>& planes,
                             const RegistrationConfig& rc) {
  std::vector<PlaneInfo> infos;
  for (const auto& p : planes) infos.push_back(Info(p, rc));
  return infos;
}

/// Appends to `mine` the orientations of current plane j (as is, and flipped when it passes close
/// to the sensor) that pass the angle and offset gates against previous plane i under the prior.
void GatePair(int i, int j, const PlaneInfo& a, const PlaneInfo& b, const Eigen::Matrix3d& R0,
              const Eigen::Vector3d& t0, const AssociationConfig& config,
              std::vector<Candidate>* mine) {
  const double cos_gate = std::cos(config.max_normal_angle_deg * kDeg);
  for (int flip = 0; flip < 2; ++flip) {
    if (flip && !(b.d < config.flip_max_offset)) break;
    Candidate c;
    c.i = i;
    c.j = j;
    c.flip = flip != 0;
    c.n_b = flip ? Eigen::Vector3d(-b.n) : b.n;
    c.d_b = flip ? -b.d : b.d;
    const Eigen::Vector3d n_pred = R0 * c.n_b;
    const double cosang = std::clamp(a.n.dot(n_pred), -1.0, 1.0);
    if (cosang < cos_gate) continue;
    const double d_err = a.d - (c.d_b + n_pred.dot(t0));
    if (std::abs(d_err) > config.max_offset_difference) continue;
    const double ang = std::acos(cosang) / (config.max_normal_angle_deg * kDeg);
    const double off = d_err / config.max_offset_difference;
    c.score = ang * ang + off * off;
    mine->push_back(c);
  }
}

/// True when the in-plane extents of two planes differ by more than the configured ratio.
bool ExtentsDisagree(const PlaneInfo& a, const PlaneInfo& b, const AssociationConfig& config) {
  if (!(config.max_extent_ratio > 0 && a.extent > 0 && b.extent > 0)) return false;
  const double ratio = std::max(a.extent, b.extent) / std::min(a.extent, b.extent);
  return ratio > config.max_extent_ratio;
}

/// Step 1: the gated candidates, for each previous plane its best `max_candidates_per_plane`
/// by gate score, grouped by previous plane in index order.
std::vector<Candidate> GatedCandidates(const std::vector<PlaneInfo>& ia,
                                       const std::vector<PlaneInfo>& ib, const MotionPrior& prior,
                                       const AssociationConfig& config) {
  const Eigen::Matrix3d R0 = prior.T_prev_curr.linear();
  const Eigen::Vector3d t0 = prior.T_prev_curr.translation();
  std::vector<Candidate> cands;
  for (int i = 0; i < static_cast<int>(ia.size()); ++i) {
    if (!ia[i].ok) continue;
    std::vector<Candidate> mine;
    for (int j = 0; j < static_cast<int>(ib.size()); ++j) {
      if (!ib[j].ok || ExtentsDisagree(ia[i], ib[j], config)) continue;
      GatePair(i, j, ia[i], ib[j], R0, t0, config, &mine);
    }
    std::stable_sort(mine.begin(), mine.end(),
                     [](const Candidate& a, const Candidate& b) { return a.score < b.score; });
    if (static_cast<int>(mine.size()) > config.max_candidates_per_plane) {
      mine.resize(config.max_candidates_per_plane);
    }
    cands.insert(cands.end(), mine.begin(), mine.end());
  }
  return cands;
}

/// Tolerances of the pairwise check that do not depend on the pair.
struct PairTolerances {
  Eigen::Vector3d t0 = Eigen::Vector3d::Zero();  ///< prior translation [m]
  double t_slack = 0.0;     ///< 3 sigma of the prior translation along its worst axis [m]
  double tol_angle0 = 0.0;  ///< base tolerance on the angle between two normals [rad]
  double parallel = 0.0;    ///< normals closer than this to (anti)parallel compare offsets [rad]
};

PairTolerances MakePairTolerances(const MotionPrior& prior, const AssociationConfig& config) {
  PairTolerances tol;
  tol.t0 = prior.T_prev_curr.translation();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es_prior(prior.covariance.topLeftCorner<3, 3>());
  const double sigma_t_prior = std::sqrt(std::max(es_prior.eigenvalues().maxCoeff(), 0.0));
  tol.t_slack = std::isfinite(sigma_t_prior) ? 3.0 * sigma_t_prior : 3.0;
  tol.tol_angle0 = config.pair_angle_tolerance_deg * kDeg;
  tol.parallel = config.parallel_angle_deg * kDeg;
  return tol;
}

/// Whether one rigid motion can explain both candidates: distinct planes on both sides, the same
/// angle between the two normals in both frames, and for (anti)parallel pairs the same offset
/// difference (sum).
bool PairConsistent(const Candidate& a, const Candidate& b, const std::vector<PlaneInfo>& ia,
                    const std::vector<PlaneInfo>& ib, const PairTolerances& tol,
                    const AssociationConfig& config) {
  if (a.i == b.i || a.j == b.j) return false;  // one-to-one
  const PlaneInfo& a1 = ia[a.i];
  const PlaneInfo& a2 = ia[b.i];
  const double ang_a = std::acos(std::clamp(a1.n.dot(a2.n), -1.0, 1.0));
  const double ang_b = std::acos(std::clamp(a.n_b.dot(b.n_b), -1.0, 1.0));
  const double var_ang = a1.var_n + a2.var_n + ib[a.j].var_n + ib[b.j].var_n;
  const double tol_angle = std::sqrt(tol.tol_angle0 * tol.tol_angle0 + 9.0 * var_ang);
  if (std::abs(ang_a - ang_b) > tol_angle) return false;
  // (Anti)parallel pairs: d_a1 -+ d_a2 = d_b1 -+ d_b2 + (n_a1 -+ n_a2).t, exactly for a rigid
  // motion, so the prior translation only matters through the small (n_a1 -+ n_a2).
  const bool par = ang_a < tol.parallel;
  const bool anti = ang_a > M_PI - tol.parallel;
  if (!(par || anti)) return true;
  const double s = par ? -1.0 : 1.0;
  const Eigen::Vector3d dn = a1.n + s * a2.n;
  const double e = (a1.d + s * a2.d) - (a.d_b + s * b.d_b) - dn.dot(tol.t0);
  const double var_off = a1.var_d + a2.var_d + ib[a.j].var_d + ib[b.j].var_d;
  const double limit =
      std::sqrt(config.pair_offset_tolerance * config.pair_offset_tolerance + 9.0 * var_off) +
      dn.norm() * tol.t_slack;
  return std::abs(e) <= limit;
}

/// Step 2: the pairwise consistency graph over the candidates, as adjacency bit sets.
std::vector<Bits> ConsistencyGraph(const std::vector<Candidate>& cands,
                                   const std::vector<PlaneInfo>& ia,
                                   const std::vector<PlaneInfo>& ib, const MotionPrior& prior,
                                   const AssociationConfig& config) {
  const PairTolerances tol = MakePairTolerances(prior, config);
  const int n = static_cast<int>(cands.size());
  const int words = (n + 63) / 64;
  std::vector<Bits> adj(n, Bits(words, 0));
  for (int u = 0; u < n; ++u) {
    for (int v = u + 1; v < n; ++v) {
      if (!PairConsistent(cands[u], cands[v], ia, ib, tol, config)) continue;
      adj[u][v / 64] |= std::uint64_t{1} << (v % 64);
      adj[v][u / 64] |= std::uint64_t{1} << (u % 64);
    }
  }
  return adj;
}

/// Score of a hypothesis, lowest best: consistency with the prior first (a wrong set of
/// mismatched planes can outweigh the true matches, and then jumps by decimetres against a prior
/// of centimetres), then more support, fewer degenerate directions, a smaller covariance.
using Score = std::tuple<int, double, int, double>;

/// A verified match set with its registration and score.
struct Hypothesis {
  Score score;
  std::vector<PlaneMatch> matches;
  RegistrationResult registration;
};

/// Step 4: verification of match sets against the candidates. Each set is solved, the
/// candidates whose residual (with the motion's own uncertainty) passes the chi^2 gate are kept
/// one-to-one, best first, and the set is re-solved and scored.
class Verifier {
 public:
  Verifier(const std::vector<detection::Plane>& prev, const std::vector<detection::Plane>& curr,
           const std::vector<Candidate>& cands, const MotionPrior& prior,
           const AssociationConfig& config, const RegistrationConfig& rc)
      : prev_(prev), curr_(curr), cands_(cands), prior_(prior), config_(config), rc_(rc) {
    // Every candidate's residual form, once: each verification tests all of them.
    match_data_.resize(cands.size());
    usable_.resize(cands.size());
    for (std::size_t k = 0; k < cands.size(); ++k) {
      candidate_of_[{cands[k].i, cands[k].j, cands[k].flip}] = static_cast<int>(k);
      usable_[k] = internal::MakeMatchData(prev_, curr_, ToMatch(static_cast<int>(k)), rc_,
                                           &match_data_[k]);
    }
  }

  PlaneMatch ToMatch(int k) const { return PlaneMatch{cands_[k].i, cands_[k].j, cands_[k].flip}; }

  /// The candidate a match came from (every match here is one of them).
  int CandidateOf(const PlaneMatch& m) const {
    const auto it = candidate_of_.find({m.prev, m.curr, m.flip_curr});
    PLANESLAM_CHECK(it != candidate_of_.end(), "a match that is no candidate");
    return it->second;
  }

  /// The matches of a clique, in the clique's order.
  std::vector<PlaneMatch> CliqueMatches(const std::vector<int>& clique) const {
    std::vector<PlaneMatch> matches;
    for (int k : clique) matches.push_back(ToMatch(k));
    return matches;
  }

  /// The matches of candidates `ks`, sorted by (prev, curr).
  std::vector<PlaneMatch> AsMatches(const std::vector<int>& ks) const {
    std::vector<PlaneMatch> matches;
    for (int k : ks) matches.push_back(ToMatch(k));
    std::sort(matches.begin(), matches.end(), [](const PlaneMatch& x, const PlaneMatch& y) {
      return std::tie(x.prev, x.curr) < std::tie(y.prev, y.curr);
    });
    return matches;
  }

  /// Whitened residual (chi^2, 3 dof) of candidate k under motion (R, t) of covariance `cov`.
  double CandidateChi2(int k, const Eigen::Matrix3d& R, const Eigen::Vector3d& t,
                       const Matrix6d& cov) const {
    if (!usable_[static_cast<std::size_t>(k)]) return std::numeric_limits<double>::infinity();
    const internal::Linearized lin =
        internal::Linearize(match_data_[static_cast<std::size_t>(k)], R, t, rc_);
    const Eigen::Matrix3d s = lin.cov + lin.J * cov * lin.J.transpose();
    Eigen::Matrix3d L;
    const double c2 = Cholesky3(s, &L)
                          ? L.triangularView<Eigen::Lower>().solve(lin.r).squaredNorm()
                          : lin.r.dot(s.ldlt().solve(lin.r));
    return std::isfinite(c2) ? c2 : std::numeric_limits<double>::infinity();
  }

  /// Candidates consistent with motion (R, t) of covariance `cov`, one-to-one, best first.
  std::vector<int> ConsistentWith(const Eigen::Matrix3d& R, const Eigen::Vector3d& t,
                                  const Matrix6d& cov) const {
    std::vector<std::pair<double, int>> chi2;
    for (int k = 0; k < static_cast<int>(cands_.size()); ++k) {
      const double c2 = CandidateChi2(k, R, t, cov);
      if (c2 <= config_.inlier_chi2) chi2.emplace_back(c2, k);
    }
    std::stable_sort(chi2.begin(), chi2.end());
    std::vector<char> used_a(prev_.size(), 0), used_b(curr_.size(), 0);
    std::vector<int> verified;
    for (const auto& [c2, k] : chi2) {
      if (used_a[cands_[k].i] || used_b[cands_[k].j]) continue;
      used_a[cands_[k].i] = used_b[cands_[k].j] = 1;
      verified.push_back(k);
    }
    return verified;
  }

  /// Support of a match set: each match weighs as its smaller plane's pixel count (1 when
  /// unknown), so the consensus is counted in evidence, not in planes: a few small facets of a
  /// curved surface, which slide as the sensor moves and agree on a wrong motion, do not outvote
  /// two large walls.
  double Support(const std::vector<PlaneMatch>& matches) const {
    double s = 0.0;
    for (const auto& m : matches) {
      s += static_cast<double>(std::max<std::int64_t>(
          1, std::min(prev_[m.prev].point_count, curr_[m.curr].point_count)));
    }
    return s;
  }

  /// RegisterPlanes of `matches` (in that order), each set solved once: tied cliques often
  /// verify to the same set, and the set grown from the prior was solved while growing.
  const RegistrationResult& Solve(const std::vector<PlaneMatch>& matches) const {
    std::vector<std::tuple<int, int, bool>> key;
    key.reserve(matches.size());
    for (const PlaneMatch& m : matches) key.emplace_back(m.prev, m.curr, m.flip_curr);
    auto it = solved_.find(key);
    if (it == solved_.end()) {
      // The matches' residual forms were made once per candidate (RegisterPlanes would make
      // them again for every subset).
      std::vector<internal::MatchData> data;
      data.reserve(matches.size());
      for (const PlaneMatch& m : matches) {
        const std::size_t k = static_cast<std::size_t>(CandidateOf(m));
        if (usable_[k]) data.push_back(match_data_[k]);
      }
      it = solved_.emplace(std::move(key), internal::RegisterMatchData(data, prior_, rc_)).first;
    }
    return it->second;
  }

  /// Solves `matches`, keeps the candidates the solution explains, re-solves with those when they
  /// differ from `matches`, and scores the result.
  Hypothesis Evaluate(const std::vector<PlaneMatch>& matches) const {
    Hypothesis h;
    h.registration = Solve(matches);
    h.matches = AsMatches(ConsistentWith(h.registration.T_prev_curr.linear(),
                                         h.registration.T_prev_curr.translation(),
                                         h.registration.covariance));
    if (!(h.matches.size() == matches.size() &&
          std::is_permutation(h.matches.begin(), h.matches.end(), matches.begin()))) {
      h.registration = Solve(h.matches);
    }
    const RegistrationResult& reg = h.registration;
    const bool off_prior =
        config_.prior_gate_chi2 > 0 && PriorInnovationChi2(reg, prior_) > config_.prior_gate_chi2;
    h.score = Score{off_prior ? 1 : 0, -Support(h.matches),
                    static_cast<int>(reg.degenerate_directions.size()), LogDet(reg.covariance)};
    return h;
  }

  /// A set grown from the matches the prior predicts, best first, keeping a match only when the
  /// solution with it still explains every kept match. It is the answer when no maximum clique
  /// agrees with the prior, and it competes with them on support otherwise (the clique search
  /// keeps only sets of the largest size in planes, which need not be the largest in support).
  std::vector<int> GrowFromPrior() const {
    std::vector<int> kept;
    for (int k : ConsistentWith(prior_.T_prev_curr.linear(), prior_.T_prev_curr.translation(),
                                prior_.covariance)) {
      std::vector<int> trial = kept;
      trial.push_back(k);
      const RegistrationResult& reg = Solve(AsMatches(trial));
      const Eigen::Matrix3d R = reg.T_prev_curr.linear();
      const Eigen::Vector3d t = reg.T_prev_curr.translation();
      const bool explained = std::all_of(trial.begin(), trial.end(), [&](int j) {
        return CandidateChi2(j, R, t, reg.covariance) <= config_.inlier_chi2;
      });
      if (explained) kept = std::move(trial);
    }
    return kept;
  }

 private:
  const std::vector<detection::Plane>& prev_;
  const std::vector<detection::Plane>& curr_;
  const std::vector<Candidate>& cands_;
  const MotionPrior& prior_;
  const AssociationConfig& config_;
  const RegistrationConfig& rc_;
  std::vector<internal::MatchData> match_data_;  ///< per candidate
  std::vector<char> usable_;                     ///< per candidate: match_data_ is valid
  std::map<std::tuple<int, int, bool>, int> candidate_of_;  ///< (prev, curr, flip) -> candidate
  mutable std::map<std::vector<std::tuple<int, int, bool>>, RegistrationResult> solved_;
};

/// Keeps `h` in `best` when there is none yet or `h` scores lower (earlier ones win ties).
void KeepBetter(std::optional<Hypothesis>* best, Hypothesis h) {
  if (!*best || h.score < (*best)->score) *best = std::move(h);
}

}  // namespace

AssociationResult AssociatePlanes(const std::vector<detection::Plane>& prev,
                                  const std::vector<detection::Plane>& curr,
                                  const MotionPrior& prior, const AssociationConfig& config,
                                  const RegistrationConfig& rc) {
  AssociationResult out;
  const std::vector<PlaneInfo> ia = Infos(prev, rc);
  const std::vector<PlaneInfo> ib = Infos(curr, rc);

  // 1. Gated candidates.
  const std::vector<Candidate> cands = GatedCandidates(ia, ib, prior, config);
  out.candidates = static_cast<int>(cands.size());
  if (cands.empty()) {
    out.registration = RegisterPlanes(prev, curr, {}, prior, rc);
    return out;
  }

  // 2. Pairwise consistency graph; 3. its maximum cliques, the largest consistent sets.
  const std::vector<Bits> adj = ConsistencyGraph(cands, ia, ib, prior, config);
  CliqueSearch search(adj, static_cast<int>(cands.size()), config.max_tied_cliques,
                      config.max_search_nodes);
  search.Run();
  out.search_exhausted = search.exhausted();
  out.tied_cliques = static_cast<int>(search.cliques().size());
  out.clique_size = search.cliques().empty() ? 0 : static_cast<int>(search.cliques()[0].size());

  // 4. Verify each tied clique and the set grown from the prior; keep the best scored.
  const Verifier verifier(prev, curr, cands, prior, config, rc);
  std::optional<Hypothesis> best;
  for (const auto& clique : search.cliques()) {
    KeepBetter(&best, verifier.Evaluate(verifier.CliqueMatches(clique)));
  }
  if (!best) {
    out.registration = RegisterPlanes(prev, curr, {}, prior, rc);
    return out;
  }
  const std::vector<int> kept = verifier.GrowFromPrior();
  if (!kept.empty()) KeepBetter(&best, verifier.Evaluate(verifier.AsMatches(kept)));
  out.prior_inconsistent = std::get<0>(best->score) == 1;
  out.matches = best->matches;
  out.registration = best->registration;
  return out;
}

std::vector<PlaneMatch> PlausibleMatches(const std::vector<detection::Plane>& prev,
                                         const std::vector<detection::Plane>& curr,
                                         const std::vector<PlaneMatch>& matches,
                                         const MotionPrior& motion,
                                         const RegistrationConfig& config) {
  const Pose& T = motion.T_prev_curr;
  const Eigen::Matrix3d translation_cov = motion.covariance.topLeftCorner<3, 3>();
  const double rotation_var = motion.covariance.bottomRightCorner<3, 3>().trace() / 3.0;
  const double normal_floor = 2.0 * config.min_normal_sigma * config.min_normal_sigma;
  const double offset_floor = 2.0 * config.min_offset_sigma * config.min_offset_sigma;
  const double gate = internal::Chi2Quantile999(2.0);
  std::vector<PlaneMatch> plausible;
  for (const PlaneMatch& m : matches) {
    const detection::Plane& p = prev.at(static_cast<std::size_t>(m.prev));
    const detection::Plane& c = curr.at(static_cast<std::size_t>(m.curr));
    const Eigen::Matrix4d cov_p =
        config.covariance_scale * PlaneCovarianceOrFallback(p, config.fallback_point_sigma);
    const Eigen::Matrix4d cov_c =
        config.covariance_scale * PlaneCovarianceOrFallback(c, config.fallback_point_sigma);
    const double sign = m.flip_curr ? -1.0 : 1.0;
    const PlaneParams moved = TransformPlane(T, sign * c.normal, sign * c.d);
    const Eigen::Vector3d& n = moved.normal;
    const double d = moved.d;
    const double angle = std::acos(std::clamp(n.dot(p.normal), -1.0, 1.0));
    // Per tangent axis: half the trace of a unit normal's (rank-2) covariance.
    const double angle_var =
        0.5 * (cov_p.topLeftCorner<3, 3>().trace() + cov_c.topLeftCorner<3, 3>().trace()) +
        normal_floor + rotation_var;
    const double offset_var = cov_p(3, 3) + cov_c(3, 3) + offset_floor +
                              n.dot(translation_cov * n) +
                              rotation_var * (T * c.centroid).squaredNorm();
    const double chi2 = angle * angle / angle_var + (d - p.d) * (d - p.d) / offset_var;
    if (chi2 <= gate) plausible.push_back(m);
  }
  return plausible;
}

}  // namespace planeslam::registration
