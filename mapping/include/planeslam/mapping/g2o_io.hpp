#pragma once
/// g2o pose graph files (3D): the format of g2o and of Ceres' pose_graph_3d example.
///
///     VERTEX_SE3:QUAT id x y z qx qy qz qw
///     EDGE_SE3:QUAT a b x y z qx qy qz qw  I11 I12 .. I16 I22 .. I26 I33 .. I66   (21 values)
///     FIX id [id ...]
///
/// Information convention: g2o's rotation error of an edge is vec(dq) (about half the angle) while
/// ours (pose_graph.hpp) is 2 vec(dq). For the same cost, our information is S I_g2o S with
/// S = diag(1, 1, 1, 1/2, 1/2, 1/2): rotation block / 4, translation-rotation blocks / 2. Reading
/// applies S, writing undoes it; both are exact in binary floating point, so reading a file and
/// writing it back reproduces every number of the file.
///
/// Edge kinds are not stored by g2o: an edge from id a to id a+1 is read as odometry, any other as
/// a loop closure (the usual layout of SLAM pose graphs).
#include <iosfwd>
#include <string>

#include "planeslam/mapping/pose_graph.hpp"

namespace planeslam::mapping {

/// Parses g2o text from `in`; `name` names the source in errors. Throws IoError(name, line, reason)
/// on a malformed line: unknown tag, wrong number of values, text where a number is expected,
/// non-finite values, a zero or far-from-unit quaternion (|norm - 1| > 0.01), duplicate vertex ids,
/// an edge or FIX naming an unknown vertex, an information matrix that is not positive definite.
/// Blank lines and lines starting with '#' are skipped.
PoseGraph ParseG2o(std::istream& in, const std::string& name);

/// Reads a g2o file; throws IoError when it cannot be opened or is malformed.
PoseGraph ReadG2o(const std::string& path);

/// The graph as g2o text, each number the shortest text that reads back exactly.
std::string FormatG2o(const PoseGraph& graph);

/// Writes FormatG2o(graph) to `path` atomically; throws IoError on failure.
void WriteG2o(const PoseGraph& graph, const std::string& path);

/// Information conversions between g2o's and our residual convention (see the file comment).
Matrix6d InformationFromG2o(const Matrix6d& g2o_information);
Matrix6d InformationToG2o(const Matrix6d& information);

}  // namespace planeslam::mapping
