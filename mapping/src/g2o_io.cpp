// g2o 3D pose graph reader and writer (format in g2o_io.hpp).
#include "planeslam/mapping/g2o_io.hpp"

#include <Eigen/Cholesky>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <istream>
#include <sstream>
#include <string_view>
#include <vector>

#include "planeslam/datasets/atomic_file.hpp"
#include "planeslam/datasets/errors.hpp"

namespace planeslam::mapping {
namespace {

constexpr const char* kVertexTag = "VERTEX_SE3:QUAT";
constexpr const char* kEdgeTag = "EDGE_SE3:QUAT";
constexpr const char* kFixTag = "FIX";
constexpr int kEdgeValues = 2 + 7 + 21;
constexpr int kVertexValues = 1 + 7;
/// Accepted deviation of a quaternion's norm from 1 (files print few digits; g2o normalises).
constexpr double kQuaternionNormTolerance = 1e-2;

/// S of the header: scales rotation rows/columns by 1/2.
Eigen::Matrix<double, 6, 1> ConventionScale() {
  Eigen::Matrix<double, 6, 1> s;
  s << 1.0, 1.0, 1.0, 0.5, 0.5, 0.5;
  return s;
}

class LineParser {
 public:
  LineParser(const std::string& name, long line, std::vector<std::string_view> tokens)
      : name_(name), line_(line), tokens_(std::move(tokens)) {}

  void ExpectCount(std::size_t count, const std::string& what) const {
    if (tokens_.size() - 1 != count) {
      Fail(what + " expects " + std::to_string(count) + " values, got " +
           std::to_string(tokens_.size() - 1));
    }
  }

  // from_chars reads the plain decimal forms of g2o files fast and rounds as strtod does;
  // anything else (a leading '+', hex, inf, out of range) takes the strtod path.
  std::int64_t Id(std::size_t i) const {
    const std::string_view t = tokens_[i];
    long long v = 0;
    const auto fast = std::from_chars(t.data(), t.data() + t.size(), v);
    if (fast.ec == std::errc() && fast.ptr == t.data() + t.size()) return v;
    const std::string text(t);
    errno = 0;
    char* end = nullptr;
    v = std::strtoll(text.c_str(), &end, 10);
    if (text.empty() || *end != '\0' || errno == ERANGE)
      Fail("expected an integer id, got '" + text + "'");
    return static_cast<std::int64_t>(v);
  }

  double Number(std::size_t i) const {
    const std::string_view t = tokens_[i];
    double v = 0.0;
    const auto fast = std::from_chars(t.data(), t.data() + t.size(), v);
    if (fast.ec == std::errc() && fast.ptr == t.data() + t.size() && std::isfinite(v)) return v;
    const std::string text(t);
    char* end = nullptr;
    v = std::strtod(text.c_str(), &end);
    if (text.empty() || *end != '\0') Fail("expected a number, got '" + text + "'");
    if (!std::isfinite(v)) Fail("non-finite value '" + text + "'");
    return v;
  }

  /// x y z qx qy qz qw from token `i`.
  void PoseAt(std::size_t i, Eigen::Vector3d& p, Eigen::Quaterniond& q) const {
    p = Eigen::Vector3d(Number(i), Number(i + 1), Number(i + 2));
    q = Eigen::Quaterniond(Number(i + 6), Number(i + 3), Number(i + 4), Number(i + 5));
    const double norm = q.norm();
    if (!(std::abs(norm - 1.0) <= kQuaternionNormTolerance)) {
      std::ostringstream os;
      os << "quaternion is not unit (norm " << norm << ")";
      Fail(os.str());
    }
  }

  [[noreturn]] void Fail(const std::string& reason) const { throw IoError(name_, line_, reason); }

  const std::vector<std::string_view>& tokens() const { return tokens_; }
  long line() const { return line_; }

 private:
  const std::string& name_;
  long line_;
  std::vector<std::string_view> tokens_;
};

struct PendingEdge {
  long line;
  PoseGraphEdge edge;
};

struct PendingFix {
  long line;
  std::int64_t id;
};

void AppendNumber(std::string& out, double v) {
  char buffer[40];
  buffer[0] = ' ';
  // The shortest text strtod reads back as the same double (IEEE 754 round trip).
  const auto result = std::to_chars(buffer + 1, buffer + sizeof(buffer), v);
  out.append(buffer, result.ptr);
}

/// Splits a line at the characters isspace() accepts in the C locale (what >> skips).
/// The tokens view `text`, which must outlive them.
void SplitTokens(const std::string& text, std::vector<std::string_view>* tokens) {
  tokens->clear();
  const auto space = [](char c) {
    return c == ' ' || c == '\t' || c == '\n' || c == '\v' || c == '\f' || c == '\r';
  };
  std::size_t i = 0;
  while (i < text.size()) {
    while (i < text.size() && space(text[i])) ++i;
    std::size_t j = i;
    while (j < text.size() && !space(text[j])) ++j;
    if (j > i) tokens->emplace_back(text.data() + i, j - i);
    i = j;
  }
}

}  // namespace

Matrix6d InformationFromG2o(const Matrix6d& g2o_information) {
  const auto s = ConventionScale();
  return s.asDiagonal() * g2o_information * s.asDiagonal();
}

Matrix6d InformationToG2o(const Matrix6d& information) {
  const Eigen::Matrix<double, 6, 1> s_inverse = ConventionScale().cwiseInverse();
  return s_inverse.asDiagonal() * information * s_inverse.asDiagonal();
}

PoseGraph ParseG2o(std::istream& in, const std::string& name) {
  PoseGraph graph;
  std::vector<PendingEdge> edges;
  std::vector<PendingFix> fixes;
  std::string text;
  long line_number = 0;
  while (std::getline(in, text)) {
    ++line_number;
    std::vector<std::string_view> tokens;
    SplitTokens(text, &tokens);
    if (tokens.empty() || tokens[0][0] == '#') continue;
    const LineParser line(name, line_number, std::move(tokens));
    const std::string_view tag = line.tokens()[0];
    if (tag == kVertexTag) {
      line.ExpectCount(kVertexValues, kVertexTag);
      PoseGraphNode node;
      node.id = line.Id(1);
      line.PoseAt(2, node.position, node.rotation);
      if (graph.HasNode(node.id)) line.Fail("duplicate vertex id " + std::to_string(node.id));
      graph.AddNode(node);
    } else if (tag == kEdgeTag) {
      line.ExpectCount(kEdgeValues, kEdgeTag);
      PendingEdge pending{line_number, {}};
      PoseGraphEdge& edge = pending.edge;
      edge.from = line.Id(1);
      edge.to = line.Id(2);
      if (edge.from == edge.to) {
        line.Fail("edge connects vertex " + std::to_string(edge.from) + " to itself");
      }
      line.PoseAt(3, edge.translation, edge.rotation);
      Matrix6d g2o_information;
      std::size_t k = 10;
      for (int r = 0; r < 6; ++r) {
        for (int c = r; c < 6; ++c) {
          g2o_information(r, c) = g2o_information(c, r) = line.Number(k++);
        }
      }
      edge.information = InformationFromG2o(g2o_information);
      // Eigen's LLT reports success on NaN pivots (overflow of huge entries): check the factor.
      const Eigen::LLT<Matrix6d> llt(edge.information);
      if (g2o_information.llt().info() != Eigen::Success || llt.info() != Eigen::Success ||
          !Matrix6d(llt.matrixL()).allFinite()) {
        line.Fail("information matrix is not positive definite");
      }
      edge.kind = edge.to == edge.from + 1 ? EdgeKind::kOdometry : EdgeKind::kLoopClosure;
      edges.push_back(std::move(pending));
    } else if (tag == kFixTag) {
      if (line.tokens().size() < 2) line.Fail("FIX expects at least one vertex id");
      for (std::size_t i = 1; i < line.tokens().size(); ++i) {
        fixes.push_back({line_number, line.Id(i)});
      }
    } else {
      line.Fail("unknown tag '" + std::string(tag) +
                "' (supported: VERTEX_SE3:QUAT, EDGE_SE3:QUAT, FIX)");
    }
  }
  if (in.bad()) throw IoError(name, "read error");
  // Edges and FIX may precede their vertices in g2o files, so they are resolved at the end.
  for (const auto& pending : edges) {
    for (std::int64_t id : {pending.edge.from, pending.edge.to}) {
      if (!graph.HasNode(id)) {
        throw IoError(name, pending.line, "edge refers to unknown vertex id " + std::to_string(id));
      }
    }
    graph.AddEdge(pending.edge);
  }
  for (const auto& fix : fixes) {
    if (!graph.HasNode(fix.id)) {
      throw IoError(name, fix.line, "FIX refers to unknown vertex id " + std::to_string(fix.id));
    }
    graph.node(fix.id).fixed = true;
  }
  return graph;
}

PoseGraph ReadG2o(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw IoError(path, "cannot open g2o file");
  return ParseG2o(in, path);
}

std::string FormatG2o(const PoseGraph& graph) {
  std::string out;
  out.reserve(graph.nodes().size() * 140 + graph.edges().size() * 600);
  auto append_pose = [&out](const Eigen::Vector3d& p, const Eigen::Quaterniond& q) {
    for (int i = 0; i < 3; ++i) AppendNumber(out, p[i]);
    AppendNumber(out, q.x());
    AppendNumber(out, q.y());
    AppendNumber(out, q.z());
    AppendNumber(out, q.w());
  };
  for (const auto& node : graph.nodes()) {
    out += kVertexTag;
    out += ' ' + std::to_string(node.id);
    append_pose(node.position, node.rotation);
    out += '\n';
  }
  for (const auto& node : graph.nodes()) {
    if (node.fixed) out += std::string(kFixTag) + ' ' + std::to_string(node.id) + '\n';
  }
  for (const auto& edge : graph.edges()) {
    out += kEdgeTag;
    out += ' ' + std::to_string(edge.from) + ' ' + std::to_string(edge.to);
    append_pose(edge.translation, edge.rotation);
    const Matrix6d g2o_information = InformationToG2o(edge.information);
    for (int r = 0; r < 6; ++r) {
      for (int c = r; c < 6; ++c) AppendNumber(out, g2o_information(r, c));
    }
    out += '\n';
  }
  return out;
}

void WriteG2o(const PoseGraph& graph, const std::string& path) {
  datasets::WriteFileAtomic(path, FormatG2o(graph));
}

}  // namespace planeslam::mapping
