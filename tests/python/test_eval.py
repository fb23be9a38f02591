"""planeslam.eval against `planeslam eval ... --json` and the TUM tools' published figures."""
import json

import numpy as np
import pytest

import planeslam

STATS = ["rmse", "mean", "median", "std", "min", "max", "sse"]


def cli_json(cli, tmp_path, *args):
    out = tmp_path / "eval.json"
    cli("eval", *args, "--json", out, "-q")
    return json.loads(out.read_text())


def assert_same(result, reference):
    for key in STATS:
        assert round(result[key], 6) == round(reference[key], 6), key
        assert result[key] == pytest.approx(reference[key], rel=1e-12, abs=1e-15), key
    assert result["pairs"] == reference["pairs"]
    for key in ["metric", "semantics", "title", "pose_relation", "unit"]:
        assert result[key] == reference[key], key
    for key, value in reference["alignment"].items():
        np.testing.assert_allclose(result["alignment"][key], value, rtol=0, atol=1e-12)


@pytest.mark.parametrize("tum", [False, True])
def test_ape_equals_cli(trajectories_dir, cli, tmp_path, tum):
    gt = trajectories_dir / "freiburg1_xyz-groundtruth.txt"
    est = trajectories_dir / "freiburg1_xyz-rgbdslam.txt"
    reference = cli_json(cli, tmp_path, "ape", gt, est, "-a", *(["--tum"] if tum else []))
    result = planeslam.eval.ape(str(gt), est, tum=tum)
    assert_same(result, reference)
    assert len(result["errors"]) == result["pairs"] == len(result["stamps"])
    if tum:  # evaluate_ate.py's own figure (data README)
        assert round(result["rmse"], 6) == 0.013473 and result["pairs"] == 786
    # The same trajectories as (N, 8) arrays.
    arrays = planeslam.eval.ape(np.loadtxt(gt), np.loadtxt(est), tum=tum)
    for key in STATS:
        assert arrays[key] == pytest.approx(result[key], rel=1e-12, abs=1e-15)


def test_ape_options_follow_the_cli(trajectories_dir, cli, tmp_path):
    gt = trajectories_dir / "fr2_desk_groundtruth.txt"
    est = trajectories_dir / "fr2_desk_ORB.txt"
    reference = cli_json(cli, tmp_path, "ape", gt, est, "-as", "-r", "angle_deg",
                         "--duplicates", "last")
    result = planeslam.eval.ape(gt, est, correct_scale=True, pose_relation="angle_deg",
                                duplicates="last")
    assert_same(result, reference)


def test_rpe_equals_cli(trajectories_dir, cli, tmp_path):
    gt = trajectories_dir / "freiburg1_xyz-groundtruth.txt"
    est = trajectories_dir / "freiburg1_xyz-rgbdslam.txt"
    reference = cli_json(cli, tmp_path, "rpe", gt, est, "-d", "10", "-r", "angle_deg")
    result = planeslam.eval.rpe(gt, est, delta=10, pose_relation="angle_deg")
    assert_same(result, reference)
    for part in ("translation", "rotation_deg"):
        for key in STATS + ["pairs"]:
            assert result[part][key] == pytest.approx(reference[part][key], rel=1e-12, abs=1e-15)
    tum_ref = cli_json(cli, tmp_path, "rpe", gt, est, "--tum", "--fixed-delta")
    tum = planeslam.eval.rpe(gt, est, tum=True, fixed_delta=True)
    assert_same(tum, tum_ref)
    # evaluate_rpe.py's own figures (data README): 753 pairs, 0.021217 m, 0.934480 deg.
    assert tum["translation"]["pairs"] == 753
    assert round(tum["translation"]["rmse"], 6) == 0.021217
    assert round(tum["rotation_deg"]["rmse"], 6) == 0.934480


def test_bad_trajectories(trajectories_dir, tmp_path):
    gt = np.loadtxt(trajectories_dir / "freiburg1_xyz-groundtruth.txt")
    with pytest.raises(ValueError, match=r"\(N, 8\)"):
        planeslam.eval.ape(gt[:, :7], gt)
    nan = gt.copy()
    nan[3, 2] = np.nan
    with pytest.raises(ValueError, match="row 3: NaN"):
        planeslam.eval.ape(gt, nan)
    unsorted = gt[::-1].copy()
    with pytest.raises(ValueError, match="not after the previous"):
        planeslam.eval.ape(unsorted, gt)
    bad_q = gt.copy()
    bad_q[0, 4:] = [0, 0, 0, 2]
    with pytest.raises(ValueError, match="quaternion norm"):
        planeslam.eval.ape(bad_q, gt)
    missing = tmp_path / "missing.txt"
    with pytest.raises(OSError, match=str(missing)):
        planeslam.eval.ape(missing, gt)
    with pytest.raises(ValueError, match="pose_relation|relation"):
        planeslam.eval.ape(gt, gt, pose_relation="length")
