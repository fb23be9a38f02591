// planeslam.Slam: `planeslam run` fed frame by frame from Python (apps/run_session.hpp).
#include <pybind11/stl.h>

#include <cmath>
#include <limits>
#include <memory>
#include <mutex>

#include "detector_factory.hpp"
#include "planeslam/datasets/trajectory_io.hpp"
#include "py_common.hpp"
#include "run_session.hpp"

namespace planeslam::python {
namespace {

namespace ds = planeslam::datasets;

class Slam {
 public:
  Slam(const py::object& intrinsics, const py::object& config, const py::object& sensor,
       const py::object& method, double depth_scale, const std::string& name)
      : depth_scale_(depth_scale) {
    if (!intrinsics.is_none()) camera_ = ParseIntrinsics(intrinsics);
    if (!(depth_scale > 0.0) || !std::isfinite(depth_scale)) {
      throw std::invalid_argument("depth_scale: must be a finite number > 0 (units per metre)");
    }
    app::Config cfg = MakeConfig(config, sensor);
    std::string m = cfg.Get<app::DetectionSection>("detection").method;
    if (!method.is_none()) {
      if (!py::isinstance<py::str>(method)) throw std::invalid_argument("method: expected a str");
      m = method.cast<std::string>();
    }
    sensor_ = cfg.Get<ds::SensorConfig>("sensor");
    session_ = std::make_unique<app::RunSession>(std::move(cfg), m, name);
  }

  py::array_t<double> Track(const py::handle& depth, double stamp, const py::object& gt_pose) {
    FrameArray in = CheckFrameArray(depth, "depth");
    if (!std::isfinite(stamp)) throw std::invalid_argument("stamp: must be finite");
    std::optional<Pose> gt;
    if (!gt_pose.is_none()) gt = ParsePose(gt_pose, "gt_pose");
    if (in.kind != FrameArray::Kind::kCloud && !camera_) {
      throw std::invalid_argument("depth: a depth image needs the Slam's intrinsics");
    }
    mapping::SlamFrameResult result;
    {
      py::gil_scoped_release release;
      std::lock_guard<std::mutex> lock(mutex_);
      if (session_->finished()) {
        throw std::invalid_argument("Slam.track: finish() was called; start a new Slam");
      }
      if (index_ > 0 && !(stamp > last_stamp_)) {
        throw std::invalid_argument("stamp: " + ds::FormatRoundTrip(stamp) +
                                    " is not after the previous frame's " +
                                    ds::FormatRoundTrip(last_stamp_));
      }
      ds::Frame frame;
      frame.index = index_;
      frame.timestamp = stamp;
      frame.T_world_sensor_gt = gt;
      maker_.Make(in, camera_, depth_scale_, sensor_, &frame.cloud);
      if (index_ == 0 && gt && session_->run_config().start_at_ground_truth) {
        session_->SetInitialPose(*gt);
      }
      result = session_->Track(index_, frame);
      ++index_;
      last_stamp_ = stamp;
    }
    return PoseArray(result.T_world_sensor);
  }

  py::dict Finish() {
    mapping::PoseGraphResult r;
    {
      py::gil_scoped_release release;
      std::lock_guard<std::mutex> lock(mutex_);
      r = session_->Finish();
    }
    py::dict d;
    d["initial_cost"] = r.initial_cost;
    d["final_cost"] = r.final_cost;
    d["iterations"] = r.iterations;
    d["converged"] = r.converged;
    return d;
  }

  std::string Write(const py::object& out_dir) {
    const std::string dir = py::str(py::module_::import("os").attr("fspath")(out_dir));
    py::gil_scoped_release release;
    std::lock_guard<std::mutex> lock(mutex_);
    if (session_->frames_done() == 0) {
      throw std::invalid_argument("Slam.write: no frame tracked: nothing written");
    }
    return session_->Write(dir);
  }

  /// The estimated trajectory as (N, 8) rows t tx ty tz qx qy qz qw (qw >= 0, as the TUM file).
  py::array_t<double> Trajectory() {
    std::lock_guard<std::mutex> lock(mutex_);
    const ds::Trajectory t = session_->slam().EstimatedTrajectory();
    py::array_t<double> a({static_cast<py::ssize_t>(t.size()), py::ssize_t{8}});
    auto m = a.mutable_unchecked<2>();
    for (std::size_t i = 0; i < t.size(); ++i) {
      Eigen::Quaterniond q(t.poses[i].linear());
      q.normalize();
      if (q.w() < 0) q.coeffs() = -q.coeffs();
      const Eigen::Vector3d p = t.poses[i].translation();
      const double row[8] = {t.stamps[i], p.x(), p.y(), p.z(), q.x(), q.y(), q.z(), q.w()};
      for (int c = 0; c < 8; ++c) m(i, c) = row[c];
    }
    return a;
  }

  py::dict Stats() {
    std::lock_guard<std::mutex> lock(mutex_);
    const mapping::SlamStats& s = session_->slam().stats();
    py::dict d;
    d["frames"] = session_->frames_done();
    d["keyframes"] = s.keyframes;
    d["loop_closures"] = s.loop_closures;
    d["degenerate_frames"] = s.degenerate_frames;
    d["untracked_frames"] = s.untracked_frames;
    d["refused_frames"] = s.refused_frames;
    d["map_planes"] = session_->slam().map().size();
    return d;
  }

  std::string Method() const { return session_->detector().Name(); }
  std::string ConfigYaml() const { return session_->config().ToYaml(true); }

 private:
  std::optional<Camera> camera_;
  double depth_scale_;
  ds::SensorConfig sensor_;
  std::unique_ptr<app::RunSession> session_;
  CloudMaker maker_;
  std::size_t index_ = 0;
  double last_stamp_ = 0.0;
  std::mutex mutex_;  ///< one frame at a time: the GIL is released while it is tracked
};

}  // namespace

void RegisterSlam(py::module_& m) {
  py::class_<Slam>(m, "Slam", R"doc(Plane SLAM fed frame by frame: `planeslam run` from Python.

Slam(intrinsics, config=None, sensor=None, method=None, depth_scale=5000.0, name="python")
intrinsics: (fx, fy, cx, cy) of the depth images (None when only clouds are tracked).
config, sensor: as detect() (e.g. sensor="tum-fr3" for `planeslam run`'s TUM fr3 profile,
    which tracks at half resolution, run.decimation 2). method: the detector, default the
    config's detection.method. name: the input's name in summary.json.)doc")
      .def(py::init<const py::object&, const py::object&, const py::object&, const py::object&,
                    double, const std::string&>(),
           py::arg("intrinsics") = py::none(), py::arg("config") = py::none(),
           py::arg("sensor") = py::none(), py::arg("method") = py::none(),
           py::arg("depth_scale") = 5000.0, py::arg("name") = "python")
      .def("track", &Slam::Track, py::arg("depth"), py::arg("stamp"),
           py::arg("gt_pose") = py::none(),
           R"doc(Tracks the next frame; returns its pose T_world_sensor as a 4x4 float64 array.

depth: as detect() (uint16 or float32 image, or (H, W, 3) float32 cloud). stamp [s]: after the
previous frame's. gt_pose: optional 4x4 ground truth, for the scores write() computes (and the
first pose when run.start_at_ground_truth). The GIL is released while it runs.)doc")
      .def("finish", &Slam::Finish,
           "The final pose-graph optimisation; returns {initial_cost, final_cost, iterations, "
           "converged}. Later calls return the first result; track() is refused afterwards.")
      .def("write", &Slam::Write, py::arg("out_dir"),
           "Writes the files of `planeslam run` into out_dir (finishing first if needed): "
           "trajectory_tum.txt, trajectory_kitti.txt, plane_map.{ply,obj,json}, pose_graph.g2o, "
           "octomap.bt, config.yaml, frames.csv, summary.json and, with ground truth, "
           "metrics.json and plots/. Returns the ATE line `planeslam run` prints.")
      .def_property_readonly("trajectory", &Slam::Trajectory,
                             "(N, 8) float64 rows t tx ty tz qx qy qz qw of the frames tracked "
                             "(the current estimate, optimised after finish())")
      .def_property_readonly("stats", &Slam::Stats,
                             "dict: frames, keyframes, loop_closures, map_planes, ...")
      .def_property_readonly("method", &Slam::Method, "the detector's name")
      .def_property_readonly("config_yaml", &Slam::ConfigYaml,
                             "the effective configuration (config.yaml)");
}

}  // namespace planeslam::python
