"""planeslam.detect against `planeslam detect` on real frames, and its handling of bad input."""
import json
import os
import threading

import numpy as np
import pytest

import planeslam
from conftest import read_png, require_data


def first_tum_frame(tum_dir):
    seq = planeslam.read_sequence(tum_dir)
    stamp, depth, gt = seq[0]
    return seq, depth


def cli_detect(cli, tmp_path, input_path, *args):
    out = tmp_path / "cli"
    cli("detect", input_path, "--out", out, "-q", *args)
    return read_png(out / "labels.png"), json.loads((out / "planes.json").read_text())


def assert_planes_equal(planes, reference, tol=1e-9):
    assert len(planes) == len(reference) > 0
    for p, r in zip(planes, reference):
        assert p.id == r["id"]
        assert p.points == r["points"]
        np.testing.assert_allclose(p.normal, r["normal"], rtol=0, atol=tol)
        assert abs(p.d - r["d"]) <= tol
        np.testing.assert_allclose(p.centroid, r["centroid"], rtol=0, atol=tol)
        assert abs(p.mse - r["mse"]) <= tol
        np.testing.assert_allclose(p.eigenvalues, r["eigenvalues"], rtol=0, atol=tol)
        np.testing.assert_allclose(p.covariance, r["covariance"], rtol=0, atol=tol)


def test_first_tum_frame_equals_cli(tum_dir, cli, tmp_path):
    seq, depth = first_tum_frame(tum_dir)
    png = tum_dir / "depth" / sorted(os.listdir(tum_dir / "depth"))[0]
    labels_png, planes_json = cli_detect(cli, tmp_path, png)
    # The CLI recognises the TUM fr3 folder: its profile, and intrinsics.yaml for the camera.
    result = planeslam.detect(depth, seq.intrinsics, depth_scale=seq.depth_scale,
                              sensor="tum-fr3")
    assert result.labels.dtype == np.uint16 and result.labels.shape == depth.shape
    assert np.array_equal(result.labels, labels_png)
    assert_planes_equal(result.planes, planes_json["planes"])
    assert result.method == planes_json["method"]
    assert result.valid_pixels == planes_json["valid_pixels"]
    assert result.assigned_pixels == planes_json["assigned_pixels"]
    # The array read_sequence gives is the PNG itself.
    assert np.array_equal(depth, read_png(png))


def test_metres_and_methods_agree_with_cli(tum_dir, cli, tmp_path):
    seq, depth = first_tum_frame(tum_dir)
    png = tum_dir / "depth" / sorted(os.listdir(tum_dir / "depth"))[0]
    labels_png, planes_json = cli_detect(cli, tmp_path, png, "--method", "point")
    # float32 metres: the same division the uint16 table makes, so the same cloud.
    metres = (depth.astype(np.float64) / seq.depth_scale).astype(np.float32)
    result = planeslam.detect(metres, seq.intrinsics, method="point", sensor="tum-fr3")
    assert np.array_equal(result.labels, labels_png)
    assert_planes_equal(result.planes, planes_json["planes"])


def test_organized_cloud_equals_cli(cli, tmp_path):
    folder = require_data("organized_pcd")
    pcds = sorted(p for p in folder.iterdir() if p.name.startswith("frame_"))
    view = tmp_path / "pcd"
    view.mkdir()
    os.symlink(pcds[0], view / pcds[0].name)
    seq = planeslam.read_sequence(view)
    assert seq.intrinsics is None and len(seq) == 1
    stamp, cloud, gt = seq[0]
    assert cloud.dtype == np.float32 and cloud.shape == (480, 640, 3) and gt is None
    labels_png, planes_json = cli_detect(cli, tmp_path, pcds[0])
    result = planeslam.detect(cloud)
    assert np.array_equal(result.labels, labels_png)
    assert_planes_equal(result.planes, planes_json["planes"])


def test_config_dict_and_file_apply_like_set_and_c(tum_dir, tmp_path):
    seq, depth = first_tum_frame(tum_dir)
    k = seq.intrinsics
    coarse = planeslam.detect(depth, k, config={"grid": {"cell_size": 8}})
    yaml = tmp_path / "grid8.yaml"
    yaml.write_text("grid:\n  cell_size: 8\n")
    from_file = planeslam.detect(depth, k, config=[str(yaml)])
    assert coarse.method == from_file.method == "grid8"
    assert np.array_equal(coarse.labels, from_file.labels)
    # The configured detector is kept between calls, but an edited file is read again.
    yaml.write_text("grid:\n  cell_size: 10\n")
    assert planeslam.detect(depth, k, config=str(yaml)).method == "grid10"
    assert planeslam.detect(depth, k).method == "grid3"


def test_gil_is_released_while_detecting(tum_dir):
    seq, depth = first_tum_frame(tum_dir)
    k = seq.intrinsics
    ticks, stop = [0], threading.Event()

    def count():
        while not stop.is_set():
            ticks[0] += 1

    thread = threading.Thread(target=count)
    thread.start()
    try:
        # Another Python thread runs during a detect() call only when the GIL is released.
        advanced = 0
        for _ in range(20):
            before = ticks[0]
            planeslam.detect(depth, k)
            advanced = max(advanced, ticks[0] - before)
            if advanced > 1000:
                break
    finally:
        stop.set()
        thread.join()
    assert advanced > 1000


def test_threads_share_the_detector(tum_dir):
    seq, depth = first_tum_frame(tum_dir)
    k = seq.intrinsics
    serial = planeslam.detect(depth, k, sensor="tum-fr3")
    results = []

    def work():
        for _ in range(2):
            results.append(planeslam.detect(depth, k, sensor="tum-fr3"))

    threads = [threading.Thread(target=work) for _ in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(results) == 6
    for r in results:
        assert np.array_equal(r.labels, serial.labels)
        assert [p.d for p in r.planes] == [p.d for p in serial.planes]


BAD_INPUTS = [
    ("3-D of the wrong shape", lambda d: np.zeros((480, 640, 4), np.float32), "(H, W, 3)"),
    ("3-D uint16", lambda d: np.zeros((480, 640, 3), np.uint16), "(H, W, 3)"),
    ("float64", lambda d: d.astype(np.float64), "float64"),
    ("int32", lambda d: d.astype(np.int32), "int32"),
    ("non-contiguous slice", lambda d: d[:, ::2], "C-contiguous"),
    ("transposed", lambda d: d.T, "C-contiguous"),
    ("NaN depth", lambda d: np.where(d > 0, d / 5000.0, np.nan).astype(np.float32), "metres"),
    ("negative depth", lambda d: -(d.astype(np.float32)), "metres"),
    ("1-D", lambda d: d.ravel(), "dimension"),
    ("empty", lambda d: np.zeros((0, 640), np.uint16), "empty"),
    ("a list", lambda d: d.tolist(), "numpy array"),
]


@pytest.mark.parametrize("name,make,message", BAD_INPUTS, ids=[b[0] for b in BAD_INPUTS])
def test_bad_arrays_raise_value_error(tum_dir, name, make, message):
    seq, depth = first_tum_frame(tum_dir)
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")):
        planeslam.detect(make(depth), seq.intrinsics)


BAD_INTRINSICS = [(535.4, 539.2, 320.1), (535.4, 539.2, 320.1, 247.6, 1.0), "535 539 320 247",
                  None, (0.0, 539.2, 320.1, 247.6), (535.4, float("nan"), 320.1, 247.6),
                  ("a", "b", "c", "d"), 535.4]


@pytest.mark.parametrize("intrinsics", BAD_INTRINSICS, ids=range(len(BAD_INTRINSICS)))
def test_bad_intrinsics_raise_value_error(tum_dir, intrinsics):
    seq, depth = first_tum_frame(tum_dir)
    with pytest.raises(ValueError, match="intrinsics"):
        planeslam.detect(depth, intrinsics)


def test_bad_options_raise_with_the_cli_messages(tum_dir, tmp_path):
    seq, depth = first_tum_frame(tum_dir)
    k = seq.intrinsics
    with pytest.raises(ValueError, match="unknown detection method 'flat'|flat"):
        planeslam.detect(depth, k, method="flat")
    with pytest.raises(ValueError, match="grid.cell_siz"):
        planeslam.detect(depth, k, config={"grid": {"cell_siz": 4}})
    with pytest.raises(ValueError, match="sensor: unknown profile 'kinect'"):
        planeslam.detect(depth, k, sensor="kinect")
    missing = tmp_path / "missing.yaml"
    with pytest.raises(OSError, match=f"{missing}: no such file"):
        planeslam.detect(depth, k, config=[str(missing)])
    with pytest.raises(ValueError, match="depth_scale"):
        planeslam.detect(depth, k, depth_scale=0.0)


def test_results_describe_themselves(tum_dir):
    seq, depth = first_tum_frame(tum_dir)
    result = planeslam.detect(depth, seq.intrinsics)
    assert len(result) == len(result.planes) > 0
    assert "Detection(" in repr(result) and "Plane(id=1" in repr(result.planes[0])
    for f in (planeslam.detect, planeslam.read_sequence, planeslam.Slam, planeslam.Slam.track,
              planeslam.Slam.finish, planeslam.Slam.write, planeslam.eval.ape,
              planeslam.eval.rpe):
        assert f.__doc__ and len(f.__doc__) > 80, f
