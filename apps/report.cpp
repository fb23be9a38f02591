// report.html of `run` and `detect`: the data of an output folder as JSON, embedded with the page's
// templates and the three.js bundle (see report.hpp).
#include "report.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>

#include "planeslam/datasets/atomic_file.hpp"
#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/image_io.hpp"
#include "planeslam/datasets/pcd_io.hpp"
#include "planeslam/datasets/trajectory_eval.hpp"
#include "planeslam/datasets/trajectory_io.hpp"
#include "planeslam/mapping/g2o_io.hpp"
#include "planeslam/mapping/occupancy_map.hpp"
#include "report_assets.hpp"

namespace planeslam::app {
namespace {

namespace ds = planeslam::datasets;
namespace fs = std::filesystem;

std::string Slurp(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw IoError(path.string(), "cannot open");
  std::ostringstream os;
  os << in.rdbuf();
  return os.str();
}

nlohmann::json ReadJson(const fs::path& path) {
  try {
    return nlohmann::json::parse(Slurp(path));
  } catch (const nlohmann::json::exception& e) {
    throw IoError(path.string(), std::string("not valid JSON: ") + e.what());
  }
}

std::string Base64(const void* data, std::size_t size) {
  static const char* kAlphabet =
      "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  const auto* in = static_cast<const std::uint8_t*>(data);
  std::string out;
  out.reserve((size + 2) / 3 * 4);
  for (std::size_t i = 0; i < size; i += 3) {
    const std::uint32_t b0 = in[i];
    const std::uint32_t b1 = i + 1 < size ? in[i + 1] : 0;
    const std::uint32_t b2 = i + 2 < size ? in[i + 2] : 0;
    const std::uint32_t v = (b0 << 16) | (b1 << 8) | b2;
    out += kAlphabet[(v >> 18) & 63];
    out += kAlphabet[(v >> 12) & 63];
    out += i + 1 < size ? kAlphabet[(v >> 6) & 63] : '=';
    out += i + 2 < size ? kAlphabet[v & 63] : '=';
  }
  return out;
}

/// Points quantised to 16 bits per axis over their bounding box (below 1 mm steps for a 60 m box;
/// a third of float32's size), base64 in "xyz"; the page decodes min + q * step.
nlohmann::json PackPoints(const std::vector<Eigen::Vector3f>& points) {
  Eigen::Vector3f lo = Eigen::Vector3f::Constant(std::numeric_limits<float>::infinity());
  Eigen::Vector3f hi = -lo;
  for (const auto& p : points) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  if (points.empty()) lo = hi = Eigen::Vector3f::Zero();
  const Eigen::Vector3f step = ((hi - lo) / 65535.0f).cwiseMax(1e-6f);
  std::vector<std::uint16_t> q(points.size() * 3);
  for (std::size_t i = 0; i < points.size(); ++i) {
    for (int a = 0; a < 3; ++a) {
      const float t = std::round((points[i][a] - lo[a]) / step[a]);
      q[3 * i + a] = static_cast<std::uint16_t>(std::clamp(t, 0.0f, 65535.0f));
    }
  }
  return {{"count", points.size()},
          {"min", {lo.x(), lo.y(), lo.z()}},
          {"step", {step.x(), step.y(), step.z()}},
          {"xyz", Base64(q.data(), q.size() * sizeof(std::uint16_t))}};
}

/// Voxel-thins `points` until at most `max_points` remain, starting at `voxel` [m] and growing it
/// by the square root of the excess (surfaces: the count falls with the voxel's square).
std::vector<Eigen::Vector3f> ThinToCount(std::vector<Eigen::Vector3f> points, double voxel,
                                         std::size_t max_points) {
  if (max_points == 0) return {};
  for (int round = 0; round < 20 && points.size() > max_points; ++round) {
    const double grow = std::sqrt(static_cast<double>(points.size()) / max_points);
    voxel *= std::max(1.1, grow);
    points = mapping::VoxelDownsample(points, voxel);
  }
  if (points.size() > max_points) points.resize(max_points);
  return points;
}

/// Moves the planes' outline vertices into one packed point block ("polygon_points", see
/// PackPoints), each plane keeping only its part sizes ("parts"): a street map's 300 000 outline
/// vertices take 2.4 MB this way instead of 20 MB of JSON numbers.
void PackPolygons(nlohmann::json* data) {
  std::vector<Eigen::Vector3f> vertices;
  for (auto& plane : (*data)["planes"]) {
    nlohmann::json parts = nlohmann::json::array();
    for (const auto& polygon : plane.value("polygons", nlohmann::json::array())) {
      parts.push_back(polygon.size());
      for (const auto& v : polygon) {
        vertices.emplace_back(v.at(0).get<float>(), v.at(1).get<float>(), v.at(2).get<float>());
      }
    }
    plane.erase("polygons");
    plane["parts"] = parts;
  }
  (*data)["polygon_points"] = PackPoints(vertices);
}

nlohmann::json PoseJson(const Pose& T) {
  const Eigen::Vector3d p = T.translation();
  const Eigen::Quaterniond q(T.rotation());
  return {p.x(), p.y(), p.z(), q.x(), q.y(), q.z(), q.w()};
}

/// Keyframes in graph order and loop-closure edges as index pairs into them, from the pose graph.
void AddGraph(const fs::path& g2o, nlohmann::json* data) {
  const mapping::PoseGraph graph = mapping::ReadG2o(g2o.string());
  nlohmann::json keyframes = nlohmann::json::array(), ids = nlohmann::json::array();
  std::unordered_map<std::int64_t, std::size_t> index;
  for (const auto& node : graph.nodes()) {
    index[node.id] = keyframes.size();
    keyframes.push_back(PoseJson(node.T_world_node()));
    ids.push_back(node.id);
  }
  nlohmann::json loops = nlohmann::json::array();
  for (const auto& edge : graph.edges()) {
    if (edge.kind == mapping::EdgeKind::kLoopClosure) {
      loops.push_back({index.at(edge.from), index.at(edge.to)});
    }
  }
  (*data)["keyframes"] = keyframes;
  (*data)["keyframe_ids"] = ids;
  (*data)["loops"] = loops;
}

/// At most `max_points` evenly spaced positions of `poses`.
nlohmann::json Positions(const std::vector<Pose>& poses, std::size_t max_points) {
  nlohmann::json out = nlohmann::json::array();
  const std::size_t stride = std::max<std::size_t>(1, (poses.size() + max_points - 1) / max_points);
  for (std::size_t i = 0; i < poses.size(); i += stride) {
    const Eigen::Vector3d p = poses[i].translation();
    out.push_back({p.x(), p.y(), p.z()});
  }
  return out;
}

/// The ground truth aligned onto the estimate (SE(3) Umeyama, the alignment of the ATE the other
/// way round), so that it is drawn in the map's frame.
void AddGroundTruth(const fs::path& dir, nlohmann::json* data) {
  const fs::path gt_path = dir / "ground_truth_tum.txt";
  const fs::path est_path = dir / "trajectory_tum.txt";
  if (!fs::exists(gt_path) || !fs::exists(est_path)) return;
  const ds::Trajectory gt = ds::ReadTumTrajectory(gt_path.string());
  const ds::Trajectory est = ds::ReadTumTrajectory(est_path.string());
  ds::ApeOptions options;
  options.alignment.align = true;
  try {
    const ds::ApeResult ape =
        ds::EvaluateApe(est, gt, options, est_path.string(), gt_path.string());
    if (!ape.ok) {
      (*data)["notes"].push_back("ground truth not shown: " + ape.message);
      return;
    }
    (*data)["ground_truth"] = Positions(ape.est_poses, 20000);
  } catch (const IoError& e) {
    (*data)["notes"].push_back(std::string("ground truth not shown: ") + e.what());
  }
}

std::string Escape(std::string text) {
  std::string out;
  out.reserve(text.size());
  for (char c : text) {
    switch (c) {
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '&': out += "&amp;"; break;
      case '"': out += "&quot;"; break;
      default: out += c;
    }
  }
  return out;
}

/// The template with every placeholder replaced by its value, in one pass over the template (so
/// that text inside a value is never taken for a placeholder). Each placeholder must occur.
std::string Fill(const std::string& tmpl,
                 const std::vector<std::pair<std::string, std::string>>& values) {
  for (const auto& [key, value] : values) {
    if (tmpl.find(key) == std::string::npos) throw CheckError("report template lacks " + key);
  }
  std::string out;
  std::size_t at = 0;
  while (true) {
    std::size_t next = std::string::npos;
    const std::pair<std::string, std::string>* which = nullptr;
    for (const auto& kv : values) {
      const std::size_t p = tmpl.find(kv.first, at);
      if (p < next) {
        next = p;
        which = &kv;
      }
    }
    if (which == nullptr) break;
    out.append(tmpl, at, next - at);
    out += which->second;
    at = next + which->first.size();
  }
  out.append(tmpl, at, std::string::npos);
  return out;
}

/// `text` with every "</" written "<\/", which ends no <script> element and means the same in
/// JSON strings and JavaScript string literals.
std::string ScriptSafe(const std::string& text) {
  std::string out;
  out.reserve(text.size() + 64);
  for (std::size_t i = 0; i < text.size(); ++i) {
    out += text[i];
    if (text[i] == '<' && i + 1 < text.size() && text[i + 1] == '/') out += '\\';
  }
  return out;
}

}  // namespace

bool ReportAvailable() { return !ReportAsset("script").empty(); }

std::string ReportUnavailableReason() {
  return "report.html not written: this planeslam was built without web/node_modules (run "
         "'npm ci --prefix web', or 'make deps', and rebuild)";
}

std::string AssembleReportHtml(const std::string& title, const nlohmann::json& data) {
  return Fill(ReportAsset("html"),
              {{"{{TITLE}}", Escape(title)},
               {"/*{{STYLE}}*/", ReportAsset("style")},
               {"{{DATA}}", ScriptSafe(data.dump(-1, ' ', false,
                                                 nlohmann::json::error_handler_t::replace))},
               {"/*{{SCRIPT}}*/", ScriptSafe(ReportAsset("script"))}});
}

std::size_t WriteKeyframeCloud(
    const std::string& path,
    const std::vector<std::pair<std::int64_t, std::vector<Eigen::Vector3f>>>& clouds,
    const std::unordered_map<std::int64_t, Pose>& poses, std::size_t max_points) {
  std::vector<Eigen::Vector3f> world;
  for (const auto& [id, points] : clouds) {
    const auto it = poses.find(id);
    if (it == poses.end()) continue;
    const Eigen::Isometry3f T = it->second.cast<float>();
    for (const auto& p : points) world.push_back(T * p);
  }
  world = ThinToCount(std::move(world), 0.02, max_points);
  ds::OrganizedCloud cloud(static_cast<int>(world.size()), 1);
  cloud.points = std::move(world);
  ds::WritePcd(path, cloud);
  return cloud.size();
}

bool WriteRunReport(const std::string& dir_name, std::size_t max_cloud_points) {
  if (!ReportAvailable()) return false;
  const fs::path dir(dir_name);
  nlohmann::json data;
  data["kind"] = "run";
  data["notes"] = nlohmann::json::array();
  data["summary"] = ReadJson(dir / "summary.json");
  const nlohmann::json map = ReadJson(dir / "plane_map.json");
  if (!map.contains("planes") || !map["planes"].is_array()) {
    throw IoError((dir / "plane_map.json").string(), "no \"planes\" array");
  }
  data["planes"] = map["planes"];
  try {
    PackPolygons(&data);
  } catch (const nlohmann::json::exception& e) {
    throw IoError((dir / "plane_map.json").string(), std::string("bad polygon: ") + e.what());
  }
  AddGraph(dir / "pose_graph.g2o", &data);
  data["metrics"] = fs::exists(dir / "metrics.json") ? ReadJson(dir / "metrics.json") : nullptr;
  data["config_yaml"] = fs::exists(dir / "config.yaml") ? Slurp(dir / "config.yaml") : "";
  data["frames_csv"] = fs::exists(dir / "frames.csv") ? Slurp(dir / "frames.csv") : "";
  AddGroundTruth(dir, &data);
  nlohmann::json svgs = nlohmann::json::object();
  for (const char* name : {"trajectories.svg", "ate_over_time.svg"}) {
    if (fs::exists(dir / "plots" / name)) svgs[name] = Slurp(dir / "plots" / name);
  }
  data["svgs"] = svgs;
  if (fs::exists(dir / "keyframe_cloud.pcd") && max_cloud_points > 0) {
    ds::OrganizedCloud cloud = ds::ReadPcd((dir / "keyframe_cloud.pcd").string());
    std::vector<Eigen::Vector3f> points;
    for (const auto& p : cloud.points) {
      if (ds::OrganizedCloud::IsValid(p)) points.push_back(p);
    }
    data["cloud"] = PackPoints(ThinToCount(std::move(points), 0.02, max_cloud_points));
  }
  const std::string title =
      "planeslam run: " + data["summary"].value("input", std::string("(unknown input)"));
  ds::WriteFileAtomic((dir / "report.html").string(), AssembleReportHtml(title, data));
  return true;
}

bool WriteDetectReport(const std::string& path, const DetectReportInput& input,
                       std::size_t max_points) {
  if (!ReportAvailable()) return false;
  const ds::OrganizedCloud& cloud = *input.cloud;
  nlohmann::json data;
  data["kind"] = "detect";
  data["detect"] = input.planes;
  data["config_yaml"] = input.config_yaml;
  nlohmann::json colours = nlohmann::json::object();
  for (const auto& plane : input.planes["planes"]) {
    const int id = plane["id"].get<int>();
    const auto rgb = ds::LabelColour(id);
    colours[std::to_string(id)] = {rgb[0], rgb[1], rgb[2]};
  }
  data["colours"] = colours;
  std::vector<std::uint16_t> labels(cloud.size());
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    labels[i] = static_cast<std::uint16_t>(std::clamp((*input.labels)[i], 0, 65535));
  }
  data["image"] = {{"width", cloud.width},
                   {"height", cloud.height},
                   {"grey", Base64(input.grey->data(), input.grey->size())},
                   {"labels", Base64(labels.data(), labels.size() * 2)}};
  // Every k-th valid point, k chosen so that at most max_points remain.
  std::size_t valid = 0;
  for (const auto& p : cloud.points) valid += ds::OrganizedCloud::IsValid(p) ? 1 : 0;
  const std::size_t stride =
      max_points == 0 ? 0 : std::max<std::size_t>(1, (valid + max_points - 1) / max_points);
  std::vector<Eigen::Vector3f> points;
  std::vector<std::uint16_t> point_labels;
  std::size_t seen = 0;
  for (std::size_t i = 0; stride > 0 && i < cloud.size(); ++i) {
    if (!ds::OrganizedCloud::IsValid(cloud.points[i])) continue;
    if (seen++ % stride != 0) continue;
    points.push_back(cloud.points[i]);
    point_labels.push_back(labels[i]);
  }
  nlohmann::json packed = PackPoints(points);
  packed["labels"] = Base64(point_labels.data(), point_labels.size() * 2);
  data["cloud"] = packed;
  const std::string title = "planeslam detect: " + input.planes.value("input", std::string());
  ds::WriteFileAtomic(path, AssembleReportHtml(title, data));
  return true;
}

}  // namespace planeslam::app
