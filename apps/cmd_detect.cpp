// `planeslam detect INPUT --out DIR`: planes of one range image (depth PNG or organized PCD).
#include <algorithm>
#include <array>
#include <cctype>
#include <cstdarg>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <exception>
#include <filesystem>
#include <iostream>
#include <limits>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "cli_common.hpp"
#include "command_registry.hpp"
#include "config_sections_app.hpp"
#include "detector_factory.hpp"
#include "exit_codes.hpp"
#include "pipeline.hpp"
#include "planeslam/datasets/atomic_file.hpp"
#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/image_io.hpp"
#include "planeslam/datasets/sensor_config.hpp"
#include "planeslam/datasets/sequence_factory.hpp"
#include "report.hpp"
#include "sensor_profiles.hpp"

namespace planeslam::app {
namespace {

namespace ds = planeslam::datasets;
using Clock = std::chrono::steady_clock;

double Ms(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

/// Grey level of each valid pixel from its range (near = light), 0 for invalid pixels.
std::vector<std::uint8_t> GreyRendering(const ds::OrganizedCloud& cloud) {
  std::vector<std::uint8_t> grey(cloud.size(), 0);
  float lo = std::numeric_limits<float>::infinity(), hi = -lo;
  for (const auto& p : cloud.points) {
    if (!ds::OrganizedCloud::IsValid(p)) continue;
    const float r = p.norm();
    lo = std::min(lo, r);
    hi = std::max(hi, r);
  }
  const float span = hi > lo ? hi - lo : 1.0f;
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const auto& p = cloud.points[i];
    if (!ds::OrganizedCloud::IsValid(p)) continue;
    grey[i] = static_cast<std::uint8_t>(60 + 170 * (1.0f - (p.norm() - lo) / span));
  }
  return grey;
}

std::string PlyBytes(const ds::OrganizedCloud& cloud, const detection::Segmentation& seg,
                     const std::vector<std::uint8_t>& grey) {
  std::size_t n = 0;
  for (const auto& p : cloud.points) n += ds::OrganizedCloud::IsValid(p) ? 1 : 0;
  std::string out =
      "ply\nformat binary_little_endian 1.0\ncomment planeslam detect: colour = plane, grey = "
      "none\nelement vertex " +
      std::to_string(n) +
      "\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\n"
      "property uchar green\nproperty uchar blue\nproperty int plane_id\nend_header\n";
  const std::size_t header = out.size();
  out.resize(header + n * 19);
  char* w = out.data() + header;
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const auto& p = cloud.points[i];
    if (!ds::OrganizedCloud::IsValid(p)) continue;
    const float xyz[3] = {p.x(), p.y(), p.z()};
    std::memcpy(w, xyz, 12);  // x86/ARM hosts are little-endian, as the header says
    const std::int32_t id = seg.labels[i] >= 1 ? seg.labels[i] : 0;
    const std::array<std::uint8_t, 3> rgb =
        id > 0 ? ds::LabelColour(id) : std::array<std::uint8_t, 3>{grey[i], grey[i], grey[i]};
    std::memcpy(w + 12, rgb.data(), 3);
    std::memcpy(w + 15, &id, 4);
    w += 19;
  }
  return out;
}

nlohmann::json PlanesJson(const std::string& input, const std::string& method,
                          const ds::OrganizedCloud& cloud, const detection::Segmentation& seg,
                          std::size_t valid, std::size_t assigned, double detect_ms) {
  nlohmann::json j;
  j["input"] = input;
  j["method"] = method;
  j["frame"] = "sensor";
  j["width"] = cloud.width;
  j["height"] = cloud.height;
  j["valid_pixels"] = valid;
  j["assigned_pixels"] = assigned;
  j["detect_ms"] = detect_ms;
  nlohmann::json timings = nlohmann::json::object();
  for (const auto& [stage, ms] : seg.timings_ms) timings[stage] = ms;
  j["timings_ms"] = timings;
  j["planes"] = nlohmann::json::array();
  for (const auto& p : seg.planes) {
    nlohmann::json jp;
    jp["id"] = p.id;
    jp["normal"] = {p.normal.x(), p.normal.y(), p.normal.z()};
    jp["d"] = p.d;
    jp["centroid"] = {p.centroid.x(), p.centroid.y(), p.centroid.z()};
    jp["points"] = p.point_count;
    jp["mse"] = p.mse;
    jp["rms"] = std::sqrt(p.mse);
    jp["eigenvalues"] = {p.eigenvalues.x(), p.eigenvalues.y(), p.eigenvalues.z()};
    nlohmann::json cov = nlohmann::json::array();
    for (int r = 0; r < 4; ++r) {
      cov.push_back(
          {p.covariance(r, 0), p.covariance(r, 1), p.covariance(r, 2), p.covariance(r, 3)});
    }
    jp["covariance"] = cov;  // of (n_x, n_y, n_z, d), rank 3
    j["planes"].push_back(jp);
  }
  return j;
}

/// printf into `text`.
__attribute__((format(printf, 2, 3))) void Appendf(std::string* text, const char* format, ...) {
  char buffer[1024];
  va_list args;
  va_start(args, format);
  const int n = std::vsnprintf(buffer, sizeof(buffer), format, args);
  va_end(args);
  if (n > 0) text->append(buffer, std::min<std::size_t>(static_cast<std::size_t>(n), sizeof(buffer) - 1));
}

bool IsPng(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext == ".png";
}

/// report.html (report.enabled) beside the other outputs; a failure there is a warning.
void WriteReport(const Config& config, const std::string& path, const std::string& planes_json,
                 const ds::OrganizedCloud& cloud, const detection::Segmentation& seg,
                 const std::vector<std::uint8_t>& grey, const std::string& config_yaml) {
  const auto& report = config.Get<ReportConfig>("report");
  if (!report.enabled) return;
  if (!ReportAvailable()) {
    std::cerr << "planeslam detect: " << ReportUnavailableReason() << "\n";
    return;
  }
  try {
    DetectReportInput input{nlohmann::json::parse(planes_json), &cloud, &seg.labels, &grey,
                            config_yaml};
    WriteDetectReport(path, input, static_cast<std::size_t>(report.cloud_points));
  } catch (const std::exception& e) {
    std::cerr << "planeslam detect: warning: report.html not written: " << e.what() << "\n";
  }
}

class DetectCommand : public Command {
 public:
  std::string Name() const override { return "detect"; }
  std::string Summary() const override {
    return "Planes of one range image (depth PNG or organized PCD): labels, planes.json, PLY";
  }
  int Order() const override { return 10; }

  void Setup(CLI::App& sub) override {
    // No CLI11 file checks: the readers throw IoError naming the file (one-line error, exit 2).
    sub.add_option("input", inputs_,
                   "16-bit depth PNG or organized .pcd (or KITTI .bin); several: one folder each "
                   "under --out, named by file stem, detected in parallel")
        ->required();
    sub.add_option("-o,--out", out_, "output folder (created)")->required();
    sub.add_option("--threads", threads_,
                   "threads for several inputs (0: the machine's cores); each input's timing is "
                   "its own detection's")
        ->check(CLI::Range(0, 256));
    std::string methods;
    for (const auto& m : DetectorMethods()) methods += (methods.empty() ? "" : "|") + m;
    sub.add_option("-m,--method", method_, "detector " + methods + " (default: detection.method)")
        ->check(CLI::IsMember(DetectorMethods()));
    sub.add_option("--intrinsics", intrinsics_,
                   "camera file for a depth PNG (width height fx fy cx cy depth_scale [flip_y]); "
                   "default: intrinsics.yaml beside the image, else its dataset folder's profile, "
                   "else the sensor section set by -c/--set");
    AddSensorOption(sub, sensor_);
    AddConfigOptions(sub, options_);
    sub.footer(
        "Examples:\n"
        "  planeslam detect depth.png --intrinsics intrinsics.yaml --out det\n"
        "  planeslam detect frame.png --config config/tum_fr3.yaml --config "
        "config/detection_kinect.yaml --out det --method point\n"
        "  planeslam detect scan000.pcd --config config/laser_scan.yaml --config "
        "config/detection_laser.yaml --out det\n"
        "  planeslam detect depth/*.png --config config/tum_fr3.yaml --out det   (det/<stem>/ each)\n"
        "Writes planes.json (n.p = d in the sensor frame, covariance of (n, d)), labels.png "
        "(16-bit "
        "plane id, 0 = none),\nlabels_color.png, classes.png (grid methods: planar green, "
        "spherical blue, linear red, sparse grey),\nsegmented.ply, config.yaml and report.html (report.enabled).");
  }

  int Run() override {
    ProfileChoice profile;
    Config config = LoadConfigWithProfile(options_, sensor_, inputs_.front(), "detect", &profile);
    auto& section = config.Get<DetectionSection>("detection");
    if (!method_.empty()) section.method = method_;
    if (MaybePrintConfig(options_, config)) return 0;
    MakeDetector(section.method, config);  // a configuration error ends the command here
    if (inputs_.size() == 1) {
      const DetectOutput output = DetectOne(config, profile, inputs_.front(), out_);
      std::fputs(output.err.c_str(), stderr);
      std::fputs(output.out.c_str(), stdout);
      return 0;
    }
    // Several inputs: independent, so detected on several threads, reported in the given order;
    // an unreadable one is reported and skipped (exit 5), all unreadable is an error.
    const std::vector<std::string> names = OutputNames(inputs_);
    std::vector<DetectOutput> outputs(inputs_.size());
    std::vector<std::exception_ptr> errors(inputs_.size());
    ParallelFor(inputs_.size(), ResolveThreads(threads_), [&](std::size_t i) {
      try {
        outputs[i] = DetectOne(config, profile, inputs_[i],
                               (std::filesystem::path(out_) / names[i]).string());
      } catch (const IoError&) {
        errors[i] = std::current_exception();
      }
    });
    std::size_t failed = 0;
    for (std::size_t i = 0; i < inputs_.size(); ++i) {
      if (errors[i]) {
        if (++failed == inputs_.size()) std::rethrow_exception(errors.front());
        try {
          std::rethrow_exception(errors[i]);
        } catch (const IoError& e) {
          std::cerr << "planeslam detect: warning: skipped: " << e.what() << "\n";
        }
        continue;
      }
      std::fputs(outputs[i].err.c_str(), stderr);
      std::fputs(outputs[i].out.c_str(), stdout);
    }
    return failed > 0 ? kExitSkippedFrames : kExitSuccess;
  }

 private:
  /// What detecting one input printed: the report (stdout) and the notes (stderr).
  struct DetectOutput {
    std::string out, err;
  };

  /// The output folder name of each input: its file stem, with its position appended when
  /// another input has the same stem.
  static std::vector<std::string> OutputNames(const std::vector<std::string>& inputs) {
    std::map<std::string, int> count;
    for (const std::string& in : inputs) ++count[std::filesystem::path(in).stem().string()];
    std::vector<std::string> names;
    for (std::size_t i = 0; i < inputs.size(); ++i) {
      const std::string stem = std::filesystem::path(inputs[i]).stem().string();
      names.push_back(count[stem] > 1 ? stem + "_" + std::to_string(i + 1) : stem);
    }
    return names;
  }

  /// Detects the planes of `input` and writes its files into `out_dir`; reads only `config`, so
  /// several inputs may be detected at once.
  DetectOutput DetectOne(const Config& config, const ProfileChoice& profile,
                         const std::string& input, const std::string& out_dir) const {
    const auto& section = config.Get<DetectionSection>("detection");
    DetectOutput output;
    ds::SensorConfig sensor = config.Get<ds::SensorConfig>("sensor");
    if (IsPng(input)) {
      const std::string source = ResolveDepthCamera(input, intrinsics_, profile, &sensor);
      const ds::PinholeIntrinsics k = sensor.EffectiveIntrinsics();
      Appendf(&output.err,
                   "planeslam detect: intrinsics fx %g fy %g cx %g cy %g, depth_scale %g, from "
                   "%s\n",
                   k.fx, k.fy, k.cx, k.cy, sensor.depth_scale, source.c_str());
    }
    const auto detector = MakeDetector(section.method, config);

    const auto t0 = Clock::now();
    const ds::Frame frame = ds::LoadSingleFrame(input, sensor);
    // A frame without a single measurement is a broken input for `detect` (the detectors
    // themselves return no planes for it, as `run` needs on a dropped frame).
    if (frame.cloud.CountValid() == 0) {
      throw IoError(input, "no valid points (every pixel is invalid or out of range)");
    }
    // Detections run one at a time (reading and writing of other inputs go on beside), so each
    // input's detect time is that of its detection alone.
    std::unique_lock<std::mutex> timing(detect_mutex_);
    const auto t1 = Clock::now();
    const detection::Segmentation seg = detector->Detect(frame.cloud);
    const auto t2 = Clock::now();
    timing.unlock();
    const ds::OrganizedCloud& cloud = frame.cloud;

    // Every output is built in memory first; only then are files written (each atomically).
    std::size_t valid = 0, assigned = 0;
    ds::Image16 labels(cloud.width, cloud.height);
    for (std::size_t i = 0; i < cloud.size(); ++i) {
      if (!cloud.IsValid(i)) continue;
      ++valid;
      if (seg.labels[i] >= 1) {
        ++assigned;
        labels.data[i] = static_cast<std::uint16_t>(std::min(seg.labels[i], 65535));
      }
    }
    const std::vector<std::uint8_t> grey = GreyRendering(cloud);
    ds::ImageRgb8 colour(cloud.width, cloud.height);
    for (std::size_t i = 0; i < cloud.size(); ++i) {
      std::uint8_t* px = &colour.data[3 * i];
      px[0] = px[1] = px[2] = grey[i];
      if (seg.labels[i] >= 1) {
        const std::array<std::uint8_t, 3> rgb = ds::LabelColour(seg.labels[i]);
        for (int c = 0; c < 3; ++c) px[c] = static_cast<std::uint8_t>((3 * rgb[c] + grey[i]) / 4);
      }
    }
    const bool have_classes = !seg.cell_classes.empty() && seg.cell_size > 0;
    ds::ImageRgb8 classes(cloud.width, cloud.height);
    if (have_classes) {
      static const std::uint8_t kClassRgb[4][3] = {
          {190, 190, 190},
          {220, 30, 30},
          {30, 190, 30},
          {40, 70, 230}};  // sparse linear planar spherical
      for (int y = 0; y < cloud.height; ++y) {
        for (int x = 0; x < cloud.width; ++x) {
          const auto cls =
              seg.cell_classes[static_cast<std::size_t>(y / seg.cell_size) * seg.cells_x +
                               x / seg.cell_size];
          const std::uint8_t* rgb = kClassRgb[static_cast<int>(cls)];
          std::memcpy(&classes.data[3 * (static_cast<std::size_t>(y) * cloud.width + x)], rgb, 3);
        }
      }
    }
    const double detect_ms = Ms(t1, t2);
    const std::string json =
        PlanesJson(input, detector->Name(), cloud, seg, valid, assigned, detect_ms).dump(1) + "\n";
    const std::string ply = PlyBytes(cloud, seg, grey);
    const std::string config_yaml = config.ToYaml();

    EnsureDirectory(out_dir);
    const std::filesystem::path dir(out_dir);
    ds::WriteFileAtomic((dir / "planes.json").string(), json);
    ds::WritePng16((dir / "labels.png").string(), labels);
    ds::WritePngRgb((dir / "labels_color.png").string(), colour);
    if (have_classes) ds::WritePngRgb((dir / "classes.png").string(), classes);
    ds::WriteFileAtomic((dir / "segmented.ply").string(), ply);
    ds::WriteFileAtomic((dir / "config.yaml").string(), config_yaml);
    WriteReport(config, (dir / "report.html").string(), json, cloud, seg, grey, config_yaml);
    const auto t3 = Clock::now();

    if (!options_.quiet) {
      char line[256];
      Appendf(&output.out, "input      %s (%dx%d, %zu valid pixels)\n", input.c_str(), cloud.width,
                  cloud.height, valid);
      Appendf(&output.out, "method     %s, threshold model %s\n", detector->Name().c_str(),
                  section.threshold_model.c_str());
      Appendf(&output.out, "planes     %zu, %.1f %% of valid pixels assigned\n", seg.planes.size(),
                  valid ? 100.0 * assigned / valid : 0.0);
      std::string stages;
      for (const auto& [stage, ms] : seg.timings_ms) {
        std::snprintf(line, sizeof(line), "%s%s %.2f", stages.empty() ? "" : ", ", stage.c_str(),
                      ms);
        stages += line;
      }
      Appendf(&output.out, "time       detect %.2f ms (%s), load %.1f ms, write %.1f ms\n", detect_ms,
                  stages.c_str(), Ms(t0, t1), Ms(t2, t3));
      const std::size_t shown = std::min<std::size_t>(seg.planes.size(), 10);
      for (std::size_t i = 0; i < shown; ++i) {
        const auto& p = seg.planes[i];
        Appendf(&output.out, "  plane %2d  n = (%6.3f %6.3f %6.3f)  d = %6.3f m  %7lld px  rms %.1f mm\n",
                    p.id, p.normal.x(), p.normal.y(), p.normal.z(), p.d,
                    static_cast<long long>(p.point_count), 1000.0 * std::sqrt(p.mse));
      }
      if (seg.planes.size() > shown)
        Appendf(&output.out, "  ... %zu more in planes.json\n", seg.planes.size() - shown);
      Appendf(&output.out, "output     %s (planes.json, labels.png, labels_color.png%s, segmented.ply%s)\n",
                  out_dir.c_str(), have_classes ? ", classes.png" : "",
                  std::filesystem::exists(dir / "report.html") ? ", report.html" : "");
    }
    return output;
  }

 private:
  std::vector<std::string> inputs_;
  std::string out_;
  int threads_ = 0;
  mutable std::mutex detect_mutex_;
  std::string method_;
  std::string intrinsics_;
  std::string sensor_;
  ConfigOptions options_;
};

PLANESLAM_REGISTER_COMMAND(DetectCommand);

}  // namespace
}  // namespace planeslam::app
