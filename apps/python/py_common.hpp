#pragma once
/// What the bindings of the Python module share: configuration from Python arguments, checked
/// numpy inputs (depth images, organized clouds, poses) and their conversion to planeslam types.
/// Bad arrays raise ValueError (std::invalid_argument); planeslam's IoError raises OSError and
/// ConfigError ValueError, with the CLI's one-line messages.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "config.hpp"
#include "planeslam/datasets/depth_image.hpp"
#include "planeslam/datasets/organized_cloud.hpp"
#include "planeslam/datasets/sensor_config.hpp"
#include "planeslam/datasets/trajectory.hpp"

namespace planeslam::python {

namespace py = pybind11;

/// The effective configuration: the sensor profile `sensor` (a name as --sensor, "none", or None:
/// recognised from `input` as the CLI does, none without an input), then `config`: None, a dict
/// {section: {key: value}}, a YAML file path, or a list of paths and dicts applied in order (as
/// -c and --set). Applies the "limits" section to the readers. `profile` receives the name of
/// the profile applied (empty for none).
app::Config MakeConfig(const py::object& config, const py::object& sensor,
                       const std::string& input = "", std::string* profile = nullptr);

/// Pinhole intrinsics (fx, fy, cx, cy) [px] from a tuple/list/array of four finite numbers with
/// fx > 0 and fy != 0 (fy < 0: flipped y axis, as ICL-NUIM); ValueError otherwise.
struct Camera {
  double fx = 0, fy = 0, cx = 0, cy = 0;
};
Camera ParseIntrinsics(const py::handle& intrinsics);
/// (fx, fy, cx, cy) as a Python tuple.
py::tuple IntrinsicsTuple(const datasets::PinholeIntrinsics& k);

/// A checked frame array, read in place: a 2-D uint16 depth image (raw units), a 2-D float32
/// depth image (metres, 0 = no measurement) or an H x W x 3 float32 organized cloud (metres, NaN
/// = no measurement). All C-contiguous.
struct FrameArray {
  enum class Kind { kRaw16, kMetres, kCloud };
  Kind kind = Kind::kRaw16;
  int width = 0;
  int height = 0;
  const void* data = nullptr;
  py::array owner;  ///< keeps the buffer alive
};
/// Checks dtype, shape and layout; ValueError naming `what` and the problem otherwise.
FrameArray CheckFrameArray(const py::handle& array, const char* what);

/// Turns frame arrays into organized clouds; keeps the back-projection tables of the last
/// camera. Runs without the GIL.
class CloudMaker {
 public:
  /// `camera` is needed for depth images; `depth_scale` [units/m] for uint16 ones; depths
  /// outside the sensor section's min_depth/max_depth become invalid.
  void Make(const FrameArray& in, const std::optional<Camera>& camera, double depth_scale,
            const datasets::SensorConfig& sensor, datasets::OrganizedCloud* cloud);

 private:
  std::unique_ptr<datasets::DepthProjector> projector_;
  double scale_ = 0, min_ = 0, max_ = 0;
};

/// A 4x4 float64 array of `pose`.
py::array_t<double> PoseArray(const Pose& pose);
/// A rigid 4x4 pose from a (4, 4) array (last row 0 0 0 1, orthonormal rotation to 1e-6);
/// ValueError naming `what` otherwise.
Pose ParsePose(const py::handle& array, const char* what);

void RegisterDetect(py::module_& m);
void RegisterSlam(py::module_& m);
void RegisterEval(py::module_& m);
void RegisterSequence(py::module_& m);

}  // namespace planeslam::python
