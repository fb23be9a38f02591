// planeslam.detect: the planes of one depth image or organized cloud, as `planeslam detect`.
#include <pybind11/stl.h>

#include <algorithm>
#include <chrono>
#include <memory>
#include <vector>

#include "detector_factory.hpp"
#include "py_common.hpp"

namespace planeslam::python {
namespace {

namespace ds = planeslam::datasets;

/// What planeslam.detect returns.
struct Detection {
  py::array_t<std::uint16_t> labels;
  std::vector<detection::Plane> planes;
  std::string method;
  std::size_t valid_pixels = 0;
  std::size_t assigned_pixels = 0;
  std::vector<std::pair<std::string, double>> timings_ms;
};

/// A detector configured from the arguments of detect(), kept for the next call with the same
/// arguments (a C++ caller keeps its detector too; building one parses the profile's YAML and
/// allocates the detector's buffers anew).
struct Configured {
  ds::SensorConfig sensor;
  std::unique_ptr<const detection::PlaneDetector> detector;
};

/// What identifies a configuration: method, sensor, and each config entry (a dict by its JSON,
/// a file by its path, size and modification time, so an edited file is read again).
std::string ConfigKey(const py::object& method, const py::object& config,
                      const py::object& sensor) {
  const py::module_ os = py::module_::import("os");
  const py::module_ json = py::module_::import("json");
  std::string key = py::repr(method).cast<std::string>() + "|" +
                    py::repr(sensor).cast<std::string>();
  const bool many = py::isinstance<py::list>(config) || py::isinstance<py::tuple>(config);
  py::list entries = many ? py::list(config) : py::list();
  if (!many && !config.is_none()) entries.append(config);
  for (const py::handle& entry : entries) {
    if (py::isinstance<py::dict>(entry)) {
      key += "|" + json.attr("dumps")(entry, py::arg("sort_keys") = true).cast<std::string>();
    } else if (py::isinstance<py::str>(entry) || py::hasattr(entry, "__fspath__")) {
      const py::object path = os.attr("fspath")(entry);
      key += "|" + py::str(path).cast<std::string>();
      try {
        const py::object st = os.attr("stat")(path);
        key += ":" + py::str(st.attr("st_size")).cast<std::string>() + ":" +
               py::str(st.attr("st_mtime_ns")).cast<std::string>();
      } catch (const py::error_already_set&) {
        // A missing file: MakeConfig reports it.
      }
    } else {
      key += "|?";  // MakeConfig rejects it
    }
  }
  return key;
}

/// The configured detector for these arguments, built on first use (a few kept, most recent
/// first). Called with the GIL held, which guards the cache.
std::shared_ptr<const Configured> GetConfigured(const py::object& method, const py::object& config,
                                                const py::object& sensor) {
  static std::vector<std::pair<std::string, std::shared_ptr<const Configured>>> cache;
  const std::string key = ConfigKey(method, config, sensor);
  for (std::size_t i = 0; i < cache.size(); ++i) {
    if (cache[i].first == key) {
      std::rotate(cache.begin(), cache.begin() + i, cache.begin() + i + 1);
      return cache.front().second;
    }
  }
  app::Config cfg = MakeConfig(config, sensor);
  auto& section = cfg.Get<app::DetectionSection>("detection");
  if (!method.is_none()) {
    if (!py::isinstance<py::str>(method)) throw std::invalid_argument("method: expected a str");
    section.method = method.cast<std::string>();
  }
  auto configured = std::make_shared<Configured>();
  configured->sensor = cfg.Get<ds::SensorConfig>("sensor");
  configured->detector = app::MakeDetector(section.method, cfg);
  cache.insert(cache.begin(), {key, configured});
  if (cache.size() > 8) cache.pop_back();
  return configured;
}

/// A configured detector and the inputs of one call.
struct DetectJob {
  FrameArray in;
  std::optional<Camera> camera;
  double depth_scale = 5000.0;
  std::shared_ptr<const Configured> configured;
};

DetectJob PrepareJob(const py::handle& depth, const py::object& intrinsics, double depth_scale,
                     const py::object& method, const py::object& config,
                     const py::object& sensor) {
  DetectJob job;
  job.in = CheckFrameArray(depth, "depth");
  if (!intrinsics.is_none()) {
    job.camera = ParseIntrinsics(intrinsics);
  } else if (job.in.kind != FrameArray::Kind::kCloud) {
    throw std::invalid_argument("intrinsics: a depth image needs (fx, fy, cx, cy)");
  }
  job.depth_scale = depth_scale;
  job.configured = GetConfigured(method, config, sensor);
  return job;
}

/// Back-projection, detection and the label image (0 = no plane), without the GIL.
detection::Segmentation RunJob(DetectJob& job, std::uint16_t* labels, std::size_t* valid,
                               std::size_t* assigned) {
  thread_local CloudMaker maker;
  thread_local ds::OrganizedCloud cloud;
  maker.Make(job.in, job.camera, job.depth_scale, job.configured->sensor, &cloud);
  detection::Segmentation seg = job.configured->detector->Detect(cloud);
  std::size_t v = 0, a = 0;
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const bool ok = cloud.IsValid(i);
    const bool on_plane = ok && seg.labels[i] >= 1;
    v += ok ? 1 : 0;
    a += on_plane ? 1 : 0;
    labels[i] = on_plane ? static_cast<std::uint16_t>(std::min(seg.labels[i], 65535)) : 0;
  }
  *valid = v;
  *assigned = a;
  return seg;
}

Detection Detect(const py::handle& depth, const py::object& intrinsics, double depth_scale,
                 const py::object& method, const py::object& config, const py::object& sensor) {
  DetectJob job = PrepareJob(depth, intrinsics, depth_scale, method, config, sensor);
  Detection result;
  result.labels = py::array_t<std::uint16_t>({job.in.height, job.in.width});
  std::uint16_t* labels = result.labels.mutable_data();
  detection::Segmentation seg;
  {
    py::gil_scoped_release release;
    seg = RunJob(job, labels, &result.valid_pixels, &result.assigned_pixels);
  }
  result.planes = std::move(seg.planes);
  result.method = job.configured->detector->Name();
  result.timings_ms = std::move(seg.timings_ms);
  return result;
}

/// Median [ms] of `repeats` calls of the C++ work of planeslam.detect (back-projection,
/// detection, label image) on one frame, timed in C++: the reference for the bindings' overhead.
py::dict BenchDetectCpp(const py::handle& depth, const py::object& intrinsics, double depth_scale,
                        const py::object& method, const py::object& config,
                        const py::object& sensor, int repeats) {
  if (repeats < 1) throw std::invalid_argument("repeats: must be >= 1");
  DetectJob job = PrepareJob(depth, intrinsics, depth_scale, method, config, sensor);
  std::vector<std::uint16_t> labels(static_cast<std::size_t>(job.in.width) * job.in.height);
  std::vector<double> times;
  {
    py::gil_scoped_release release;
    for (int r = 0; r < repeats; ++r) {
      const auto t0 = std::chrono::steady_clock::now();
      std::size_t valid = 0, assigned = 0;
      const detection::Segmentation seg = RunJob(job, labels.data(), &valid, &assigned);
      times.push_back(
          std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    }
  }
  std::vector<double> sorted = times;
  std::sort(sorted.begin(), sorted.end());
  const std::size_t n = sorted.size();
  const double median = n % 2 ? sorted[n / 2] : 0.5 * (sorted[n / 2 - 1] + sorted[n / 2]);
  py::dict out;
  out["median_ms"] = median;
  out["times_ms"] = times;
  out["method"] = job.configured->detector->Name();
  return out;
}

py::array_t<double> Vec3(const Eigen::Vector3d& v) {
  py::array_t<double> a(3);
  auto m = a.mutable_unchecked<1>();
  for (int i = 0; i < 3; ++i) m(i) = v[i];
  return a;
}

void BindTypes(py::module_& m) {
  py::class_<detection::Plane>(m, "Plane",
                               "A detected plane n.p = d in the sensor frame (metres).")
      .def_readonly("id", &detection::Plane::id, "id >= 1, its value in the label image")
      .def_property_readonly(
          "normal", [](const detection::Plane& p) { return Vec3(p.normal); },
          "unit normal (3,) float64")
      .def_readonly("d", &detection::Plane::d, "offset d [m] of n.p = d")
      .def_property_readonly(
          "centroid", [](const detection::Plane& p) { return Vec3(p.centroid); },
          "mass centre of its points (3,) [m]")
      .def_readonly("points", &detection::Plane::point_count, "number of pixels assigned")
      .def_readonly("mse", &detection::Plane::mse, "mean squared point-to-plane distance [m^2]")
      .def_property_readonly(
          "eigenvalues", [](const detection::Plane& p) { return Vec3(p.eigenvalues); },
          "eigenvalues of the points' scatter matrix, ascending (3,)")
      .def_property_readonly(
          "covariance",
          [](const detection::Plane& p) {
            py::array_t<double> a({4, 4});
            auto w = a.mutable_unchecked<2>();
            for (int r = 0; r < 4; ++r) {
              for (int c = 0; c < 4; ++c) w(r, c) = p.covariance(r, c);
            }
            return a;
          },
          "covariance (4, 4) of (n_x, n_y, n_z, d), rank 3")
      .def("__repr__", [](const detection::Plane& p) {
        return py::str("Plane(id={}, normal=({:.4f}, {:.4f}, {:.4f}), d={:.4f}, points={})")
            .format(p.id, p.normal.x(), p.normal.y(), p.normal.z(), p.d, p.point_count);
      });
  py::class_<Detection>(m, "Detection", "What planeslam.detect returns.")
      .def_readonly("labels", &Detection::labels,
                    "uint16 (H, W): plane id per pixel, 0 = no plane (labels.png)")
      .def_readonly("planes", &Detection::planes, "list of Plane, planes[i].id == i + 1")
      .def_readonly("method", &Detection::method, "detector name, e.g. grid3")
      .def_readonly("valid_pixels", &Detection::valid_pixels, "pixels with a measurement")
      .def_readonly("assigned_pixels", &Detection::assigned_pixels, "pixels on a plane")
      .def_readonly("timings_ms", &Detection::timings_ms, "(stage, ms) of the detector")
      .def("__len__", [](const Detection& d) { return d.planes.size(); })
      .def("__repr__", [](const Detection& d) {
        return py::str("Detection(method={!r}, planes={}, assigned_pixels={}/{})")
            .format(d.method, d.planes.size(), d.assigned_pixels, d.valid_pixels);
      });
}

}  // namespace

void RegisterDetect(py::module_& m) {
  BindTypes(m);
  m.def("detect", &Detect, py::arg("depth"), py::arg("intrinsics") = py::none(),
        py::arg("depth_scale") = 5000.0, py::arg("method") = py::none(),
        py::arg("config") = py::none(), py::arg("sensor") = py::none(),
        R"doc(Planes of one depth image or organized cloud, as `planeslam detect`.

depth: 2-D uint16 (raw units, depth_scale per metre, 0 = none) or float32 (metres, 0 = none)
    image, or an (H, W, 3) float32 organized cloud in metres (NaN = none); C-contiguous, read
    in place.
intrinsics: (fx, fy, cx, cy) in pixels, needed for a depth image (fy < 0 flips y).
depth_scale: raw units per metre of a uint16 image (TUM 5000, millimetre images 1000).
method: grid (default: the config's detection.method), grid-fast, grid-paper, point,
    point-paper.
config: a dict {section: {key: value}}, a YAML file, or a list of them, over the defaults.
sensor: a sensor profile applied first, as --sensor (e.g. "tum-fr3").

Returns a Detection: .labels (uint16, 0 = no plane, ids as .planes), .planes (Plane: id,
normal, d, centroid, points, mse, eigenvalues, covariance). Raises ValueError on a bad array,
intrinsics or config, OSError on an unreadable config file. The GIL is released meanwhile.)doc");
  m.def("_bench_detect_cpp", &BenchDetectCpp, py::arg("depth"),
        py::arg("intrinsics") = py::none(), py::arg("depth_scale") = 5000.0,
        py::arg("method") = py::none(), py::arg("config") = py::none(),
        py::arg("sensor") = py::none(), py::arg("repeats") = 50,
        "Times the C++ work of detect() (back-projection, detection, label image) `repeats` "
        "times in C++; returns {'median_ms', 'times_ms', 'method'}. For the overhead benchmark.");
}

}  // namespace planeslam::python
