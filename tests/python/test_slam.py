"""planeslam.Slam fed from read_sequence against `planeslam run` on the same data and settings."""
import json
import os

import numpy as np
import pytest

import planeslam
from conftest import require_data

# Every file of `planeslam run` but summary.json, whose timings differ, must be byte-identical.
SAME_FILES = ["trajectory_tum.txt", "trajectory_kitti.txt", "plane_map.json", "plane_map.ply",
              "plane_map.obj", "pose_graph.g2o", "config.yaml", "frames.csv"]


def run_both(cli, folder, tmp_path):
    cli_out, py_out = tmp_path / "cli", tmp_path / "py"
    cli("run", folder, "--out", cli_out, "-q")
    seq = planeslam.read_sequence(folder)
    slam = planeslam.Slam(seq.intrinsics, sensor=seq.profile,
                          depth_scale=seq.depth_scale or 5000.0, name=str(folder))
    poses = [slam.track(depth, stamp, gt) for stamp, depth, gt in seq]
    slam.finish()
    slam.write(py_out)
    return cli_out, py_out, slam, poses


def without_timings(summary):
    summary = dict(summary)
    summary.pop("time_ms")
    summary.pop("frames_per_second")
    # The back end's time per frame over the first and last frames is a timing too.
    summary["back_end"] = {k: v for k, v in summary.get("back_end", {}).items()
                           if "_ms" not in k}
    return summary


def test_tum_run_equals_cli(tum_dir, cli, tmp_path):
    cli_out, py_out, slam, poses = run_both(cli, tum_dir, tmp_path)
    for name in SAME_FILES + ["metrics.json"]:
        assert (cli_out / name).read_bytes() == (py_out / name).read_bytes(), name
    cli_summary = json.loads((cli_out / "summary.json").read_text())
    py_summary = json.loads((py_out / "summary.json").read_text())
    assert without_timings(cli_summary) == without_timings(py_summary)
    ate = json.loads((py_out / "metrics.json").read_text())["ate"]
    assert round(ate["rmse"], 6) == round(cli_summary["metrics"]["ate"]["rmse"], 6)
    assert ate["pairs"] == 248
    # The returned poses are 4x4 rigid transforms; the trajectory property is the TUM file's.
    assert len(poses) == 252 and poses[0].shape == (4, 4)
    np.testing.assert_allclose(poses[0][3], [0, 0, 0, 1])
    tum = np.loadtxt(cli_out / "trajectory_tum.txt")
    np.testing.assert_allclose(slam.trajectory, tum, rtol=0, atol=1e-9)
    assert slam.stats["frames"] == 252 and slam.method == "grid3"
    # eval.ape on the written trajectory gives the ATE `run` reports.
    gt_rows = np.array([[stamp, *pose_row(gt)] for stamp, _, gt in planeslam.read_sequence(tum_dir)
                        if gt is not None])
    ape = planeslam.eval.ape(gt_rows, py_out / "trajectory_tum.txt")
    assert round(ape["rmse"], 6) == round(ate["rmse"], 6) and ape["pairs"] == ate["pairs"]


def pose_row(T):
    """tx ty tz qx qy qz qw of a 4x4 pose."""
    R, t = T[:3, :3], T[:3, 3]
    w = np.sqrt(max(0.0, 1.0 + R[0, 0] + R[1, 1] + R[2, 2])) / 2.0
    if w > 1e-6:
        x, y, z = (R[2, 1] - R[1, 2]) / (4 * w), (R[0, 2] - R[2, 0]) / (4 * w), \
            (R[1, 0] - R[0, 1]) / (4 * w)
    else:  # a half turn: never in this short sequence
        raise AssertionError("rotation of 180 degrees")
    return [*t, x, y, z, w]


def test_cloud_sequence_equals_cli(cli, tmp_path):
    folder = require_data("organized_pcd")
    view = tmp_path / "frames"
    view.mkdir()
    for p in sorted(folder.iterdir()):
        if p.name.startswith("frame_"):
            os.symlink(p, view / p.name)
    cli_out, py_out, slam, poses = run_both(cli, view, tmp_path)
    assert len(poses) == 3
    for name in SAME_FILES:
        assert (cli_out / name).read_bytes() == (py_out / name).read_bytes(), name


def test_tracking_errors(tum_dir, tmp_path):
    seq = planeslam.read_sequence(tum_dir)
    stamp, depth, gt = seq[0]
    slam = planeslam.Slam(seq.intrinsics, sensor="tum-fr3")
    with pytest.raises(ValueError, match="no frame tracked"):
        slam.write(tmp_path / "empty")
    assert not (tmp_path / "empty").exists()
    slam.track(depth, stamp, gt)
    with pytest.raises(ValueError, match="not after the previous"):
        slam.track(depth, stamp)
    with pytest.raises(ValueError, match="rigid"):
        slam.track(depth, stamp + 1, np.eye(4) * 2)
    with pytest.raises(ValueError, match="4x4"):
        slam.track(depth, stamp + 1, np.eye(3))
    with pytest.raises(ValueError, match="float64"):
        slam.track(depth.astype(np.float64), stamp + 1)
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(OSError, match="cannot create output directory"):
        slam.write(blocker / "out")
    slam.finish()
    with pytest.raises(ValueError, match="finish"):
        slam.track(depth, stamp + 2)
    with pytest.raises(ValueError, match="intrinsics"):
        planeslam.Slam((1.0, 2.0))
    with pytest.raises(ValueError, match="a depth image needs"):
        planeslam.Slam().track(depth, 0.0)
