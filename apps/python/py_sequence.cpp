// planeslam.read_sequence: the frames of a sequence folder as `planeslam run` reads them.
#include <pybind11/stl.h>

#include <cstring>
#include <filesystem>
#include <memory>

#include "planeslam/datasets/image_io.hpp"
#include "planeslam/datasets/sequence_factory.hpp"
#include "planeslam/datasets/tum_sequence.hpp"
#include "py_common.hpp"

namespace planeslam::python {
namespace {

namespace ds = planeslam::datasets;

class Sequence {
 public:
  Sequence(const py::object& path, const py::object& config, const py::object& sensor) {
    path_ = py::str(py::module_::import("os").attr("fspath")(path));
    const app::Config cfg = MakeConfig(config, sensor, path_, &profile_);
    sequence_ = ds::OpenSequence(path_, cfg.Get<ds::SensorConfig>("sensor"));
    depth_ = dynamic_cast<const ds::DepthImageSequence*>(sequence_.get());
  }

  std::size_t Size() const { return sequence_->Size(); }

  /// (stamp, depth or cloud, ground-truth pose or None) of frame `index` (negative: from the end).
  py::tuple Get(py::ssize_t index) const {
    const auto n = static_cast<py::ssize_t>(Size());
    if (index < 0) index += n;
    if (index < 0 || index >= n) throw py::index_error("frame index out of range");
    const auto i = static_cast<std::size_t>(index);
    py::object gt = py::none();
    if (const auto pose = sequence_->GroundTruth(i)) gt = PoseArray(*pose);
    if (depth_ != nullptr) {
      const ds::DepthImageSequence::Item& item = depth_->item(i);
      ds::Image16 image;
      {
        py::gil_scoped_release release;
        std::error_code ec;
        if (!item.list.empty() && !std::filesystem::is_regular_file(item.path, ec)) {
          throw IoError(item.list, item.list_line,
                        "names '" + item.list_entry + "' which does not exist");
        }
        image = ds::ReadPng16(item.path);
      }
      py::array_t<std::uint16_t> a({image.height, image.width});
      std::memcpy(a.mutable_data(), image.data.data(), image.data.size() * sizeof(std::uint16_t));
      return py::make_tuple(item.timestamp, a, gt);
    }
    ds::Frame frame;
    {
      py::gil_scoped_release release;
      frame = sequence_->Load(i);
    }
    const ds::OrganizedCloud& c = frame.cloud;
    py::array_t<float> a({c.height, c.width, 3});
    std::memcpy(a.mutable_data(), c.points.data(), c.points.size() * sizeof(Eigen::Vector3f));
    return py::make_tuple(frame.timestamp, a, gt);
  }

  py::object Intrinsics() const {
    if (depth_ == nullptr) return py::none();
    return IntrinsicsTuple(depth_->intrinsics());
  }
  py::object DepthScale() const {
    if (depth_ == nullptr) return py::none();
    return py::float_(depth_->depth_scale());
  }
  py::object Profile() const { return profile_.empty() ? py::object(py::none()) : py::str(profile_); }
  const std::string& Path() const { return path_; }

 private:
  std::string path_;
  std::string profile_;
  std::unique_ptr<ds::Sequence> sequence_;
  const ds::DepthImageSequence* depth_ = nullptr;
};

}  // namespace

void RegisterSequence(py::module_& m) {
  py::class_<Sequence>(m, "Sequence", "The frames of a sequence folder (see read_sequence).")
      .def("__len__", &Sequence::Size)
      .def("__getitem__", &Sequence::Get, py::arg("index"),
           "(stamp, depth, gt_pose_or_None) of one frame")
      .def_property_readonly("intrinsics", &Sequence::Intrinsics,
                             "(fx, fy, cx, cy) the depth images are back-projected with (fy < 0: "
                             "flipped y), None for cloud sequences")
      .def_property_readonly("depth_scale", &Sequence::DepthScale,
                             "raw depth units per metre, None for cloud sequences")
      .def_property_readonly("profile", &Sequence::Profile,
                             "the sensor profile applied (as `planeslam run` chooses it), or None")
      .def_property_readonly("path", &Sequence::Path, "the folder");
  m.def(
      "read_sequence",
      [](const py::object& path, const py::object& config, const py::object& sensor) {
        return Sequence(path, config, sensor);
      },
      py::arg("path"), py::arg("config") = py::none(), py::arg("sensor") = py::none(),
      R"doc(Opens a sequence folder as `planeslam run` does (TUM, ICL-NUIM, organized PCD, KITTI .bin).

Iterating it yields (stamp, depth, gt_pose_or_None): stamp [s]; depth a uint16 (H, W) image in
raw units for depth-image layouts (see .intrinsics, .depth_scale), an (H, W, 3) float32 cloud
in metres for PCD and KITTI folders; gt_pose a 4x4 float64 T_world_sensor when the ground truth
has a pose for the frame. len() and indexing work too. sensor: a profile name, "none", or None
(recognised from the folder, as the CLI); config: as detect(). Raises OSError naming the file
on unreadable data.)doc");
}

}  // namespace planeslam::python
