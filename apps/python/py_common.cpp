#include "py_common.hpp"

#include <cmath>
#include <limits>
#include <stdexcept>
#include <vector>

#include "config_sections_datasets.hpp"
#include "sensor_profiles.hpp"

namespace planeslam::python {
namespace {

namespace ds = planeslam::datasets;

std::string TypeName(const py::handle& h) {
  return py::str(py::type::handle_of(h).attr("__name__")).cast<std::string>();
}

/// One config entry: a path (str or os.PathLike) or a dict, applied to `config`. A dict is
/// dumped as JSON, which is YAML, so it is checked key by key like a config file.
void ApplyConfigEntry(const py::handle& entry, app::Config* config) {
  if (py::isinstance<py::dict>(entry)) {
    const std::string text = py::module_::import("json").attr("dumps")(entry).cast<std::string>();
    config->LoadString(text, "config dict");
    return;
  }
  if (py::isinstance<py::str>(entry) || py::hasattr(entry, "__fspath__")) {
    config->LoadFile(py::str(py::module_::import("os").attr("fspath")(entry)).cast<std::string>());
    return;
  }
  throw std::invalid_argument("config: expected a dict, a YAML file path or a list of them, got " +
                              TypeName(entry));
}

}  // namespace

app::Config MakeConfig(const py::object& config, const py::object& sensor,
                       const std::string& input, std::string* profile) {
  app::Config result;
  if (!sensor.is_none() && !py::isinstance<py::str>(sensor)) {
    throw std::invalid_argument("sensor: expected a profile name (str), got " + TypeName(sensor));
  }
  const std::string name = sensor.is_none() ? "" : sensor.cast<std::string>();
  if (!name.empty() || !input.empty()) {
    const app::ProfileChoice choice = app::ChooseProfile(name, input);
    if (choice.profile != nullptr) {
      for (const std::string& file : choice.profile->files) {
        result.LoadString(app::ConfigFiles().at(file), file);
      }
      if (profile != nullptr) *profile = choice.profile->name;
    }
  }
  if (py::isinstance<py::list>(config) || py::isinstance<py::tuple>(config)) {
    for (const py::handle& entry : config) ApplyConfigEntry(entry, &result);
  } else if (!config.is_none()) {
    ApplyConfigEntry(config, &result);
  }
  app::ApplyInputLimits(result);
  return result;
}

Camera ParseIntrinsics(const py::handle& intrinsics) {
  const char* expected = "intrinsics: expected a tuple (fx, fy, cx, cy) of four finite numbers";
  if (intrinsics.is_none() || py::isinstance<py::str>(intrinsics) ||
      (!py::isinstance<py::sequence>(intrinsics) && !py::isinstance<py::array>(intrinsics))) {
    throw std::invalid_argument(std::string(expected) + ", got " + TypeName(intrinsics));
  }
  std::vector<double> v;
  for (const py::handle& item : py::iter(intrinsics)) {
    if (!py::isinstance<py::float_>(item) && !py::isinstance<py::int_>(item) &&
        !py::hasattr(item, "__float__")) {
      throw std::invalid_argument(std::string(expected) + ", got an item of type " +
                                  TypeName(item));
    }
    v.push_back(item.cast<double>());
  }
  if (v.size() != 4) {
    throw std::invalid_argument(std::string(expected) + ", got " + std::to_string(v.size()) +
                                " values");
  }
  for (double x : v) {
    if (!std::isfinite(x)) throw std::invalid_argument(std::string(expected) + ", got NaN or inf");
  }
  if (!(v[0] > 0.0) || v[1] == 0.0) {
    throw std::invalid_argument("intrinsics: fx must be > 0 and fy != 0 (fy < 0 flips y)");
  }
  return {v[0], v[1], v[2], v[3]};
}

py::tuple IntrinsicsTuple(const ds::PinholeIntrinsics& k) {
  return py::make_tuple(k.fx, k.fy, k.cx, k.cy);
}

FrameArray CheckFrameArray(const py::handle& handle, const char* what) {
  const std::string name = what;
  if (!py::isinstance<py::array>(handle)) {
    throw std::invalid_argument(name + ": expected a numpy array, got " + TypeName(handle));
  }
  FrameArray in;
  in.owner = py::reinterpret_borrow<py::array>(handle);
  const py::array& a = in.owner;
  const std::string dtype = py::str(a.dtype()).cast<std::string>();
  const bool u16 = py::isinstance<py::array_t<std::uint16_t>>(a);
  const bool f32 = py::isinstance<py::array_t<float>>(a);
  if (a.ndim() == 2) {
    if (!u16 && !f32) {
      throw std::invalid_argument(name + ": a depth image must be uint16 (raw units) or float32 " +
                                  "(metres), got " + dtype + "; convert with .astype()");
    }
    in.kind = u16 ? FrameArray::Kind::kRaw16 : FrameArray::Kind::kMetres;
  } else if (a.ndim() == 3) {
    if (a.shape(2) != 3 || !f32) {
      throw std::invalid_argument(
          name + ": a 3-D array must be an organized cloud of shape (H, W, 3) and dtype float32, " +
          "got shape (" + std::to_string(a.shape(0)) + ", " + std::to_string(a.shape(1)) + ", " +
          std::to_string(a.shape(2)) + ") " + dtype);
    }
    in.kind = FrameArray::Kind::kCloud;
  } else {
    throw std::invalid_argument(name + ": expected a 2-D depth image or an (H, W, 3) cloud, got " +
                                std::to_string(a.ndim()) + " dimension(s)");
  }
  if (!(a.flags() & py::array::c_style)) {
    throw std::invalid_argument(name + ": the array is not C-contiguous (a slice or transpose); " +
                                "pass numpy.ascontiguousarray(" + name + ")");
  }
  if (a.shape(0) < 1 || a.shape(1) < 1 || a.shape(0) > 65535 || a.shape(1) > 65535) {
    throw std::invalid_argument(name + ": image size " + std::to_string(a.shape(1)) + "x" +
                                std::to_string(a.shape(0)) + " is empty or too large");
  }
  in.height = static_cast<int>(a.shape(0));
  in.width = static_cast<int>(a.shape(1));
  in.data = a.data();
  return in;
}

void CloudMaker::Make(const FrameArray& in, const std::optional<Camera>& camera,
                      double depth_scale, const ds::SensorConfig& sensor,
                      ds::OrganizedCloud* cloud) {
  if (in.kind == FrameArray::Kind::kCloud) {
    // Eigen::Vector3f is three packed floats, the layout of an (H, W, 3) float32 array.
    static_assert(sizeof(Eigen::Vector3f) == 3 * sizeof(float), "packed Vector3f");
    cloud->width = in.width;
    cloud->height = in.height;
    cloud->model = sensor.pcd_model == "spherical" ? ds::SensorModel::kSpherical
                                                   : ds::SensorModel::kPinhole;
    const auto* p = static_cast<const Eigen::Vector3f*>(in.data);
    cloud->points.assign(p, p + static_cast<std::size_t>(in.width) * in.height);
    for (Eigen::Vector3f& q : cloud->points) {
      if (!q.allFinite()) q.setConstant(std::numeric_limits<float>::quiet_NaN());
    }
    return;
  }
  if (!camera) throw std::invalid_argument("intrinsics: needed for a depth image");
  ds::PinholeIntrinsics k;
  k.width = in.width;
  k.height = in.height;
  k.fx = camera->fx;
  k.fy = camera->fy;
  k.cx = camera->cx;
  k.cy = camera->cy;
  if (in.kind == FrameArray::Kind::kRaw16) {
    if (!(depth_scale > 0.0) || !std::isfinite(depth_scale)) {
      throw std::invalid_argument("depth_scale: must be a finite number > 0 (units per metre)");
    }
    const ds::PinholeIntrinsics* last = projector_ ? &projector_->intrinsics() : nullptr;
    if (last == nullptr || last->width != k.width || last->height != k.height ||
        last->fx != k.fx || last->fy != k.fy || last->cx != k.cx || last->cy != k.cy ||
        scale_ != depth_scale || min_ != sensor.min_depth || max_ != sensor.max_depth) {
      projector_ = std::make_unique<ds::DepthProjector>(k, depth_scale, sensor.min_depth,
                                                        sensor.max_depth);
      scale_ = depth_scale;
      min_ = sensor.min_depth;
      max_ = sensor.max_depth;
    }
    projector_->Project(static_cast<const std::uint16_t*>(in.data), in.width, in.height, cloud,
                        "depth array");
    return;
  }
  // Metres: the pinhole model with DepthProjector's per-column and per-row factors.
  cloud->width = in.width;
  cloud->height = in.height;
  cloud->model = ds::SensorModel::kPinhole;
  cloud->points.resize(static_cast<std::size_t>(in.width) * in.height);
  std::vector<float> col(in.width);
  for (int u = 0; u < in.width; ++u) col[u] = static_cast<float>((u - k.cx) / k.fx);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float* z = static_cast<const float*>(in.data);
  Eigen::Vector3f* out = cloud->points.data();
  for (int v = 0; v < in.height; ++v) {
    const float row = static_cast<float>((v - k.cy) / k.fy);
    for (int u = 0; u < in.width; ++u, ++z, ++out) {
      if (!std::isfinite(*z) || *z < 0.0f) {
        throw std::invalid_argument(
            "depth: pixel (row " + std::to_string(v) + ", column " + std::to_string(u) + ") is " +
            std::to_string(*z) + "; a float32 depth image holds metres >= 0 (0 = no measurement)");
      }
      const double d = *z;
      const bool valid =
          d > 0.0 && d >= sensor.min_depth && (sensor.max_depth <= 0.0 || d <= sensor.max_depth);
      const float zz = valid ? *z : nan;
      *out = Eigen::Vector3f(col[u] * zz, row * zz, zz);
    }
  }
}

py::array_t<double> PoseArray(const Pose& pose) {
  py::array_t<double> a({4, 4});
  auto m = a.mutable_unchecked<2>();
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) m(r, c) = pose.matrix()(r, c);
  }
  return a;
}

Pose ParsePose(const py::handle& handle, const char* what) {
  const std::string name = what;
  if (!py::isinstance<py::array>(handle) && !py::isinstance<py::sequence>(handle)) {
    throw std::invalid_argument(name + ": expected a 4x4 array, got " + TypeName(handle));
  }
  const auto a = py::array_t<double, py::array::forcecast>::ensure(handle);
  if (!a || a.ndim() != 2 || a.shape(0) != 4 || a.shape(1) != 4) {
    throw std::invalid_argument(name + ": expected a 4x4 array");
  }
  const auto m = a.unchecked<2>();
  Eigen::Matrix4d t;
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) t(r, c) = m(r, c);
  }
  const Eigen::Matrix3d rot = t.topLeftCorner<3, 3>();
  if (!t.allFinite() || (t.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).norm() > 1e-9 ||
      (rot.transpose() * rot - Eigen::Matrix3d::Identity()).norm() > 1e-6 ||
      rot.determinant() < 0.0) {
    throw std::invalid_argument(name + ": not a rigid transform (rotation and translation, last " +
                                "row 0 0 0 1)");
  }
  Pose pose = Pose::Identity();
  pose.matrix() = t;
  return pose;
}

}  // namespace planeslam::python
