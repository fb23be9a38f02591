"""planeslam.read_sequence on the TUM folder, as `planeslam run` reads it."""
import numpy as np
import pytest

import planeslam
from conftest import read_png


def test_tum_folder(tum_dir):
    seq = planeslam.read_sequence(tum_dir)
    listed = [line.split() for line in (tum_dir / "depth.txt").read_text().splitlines()
              if line and not line.startswith("#")]
    assert len(seq) == len(listed) == 252
    assert seq.profile == "tum-fr3" and seq.depth_scale == 5000.0
    assert seq.intrinsics == (535.4, 539.2, 320.1, 247.6)
    frames = list(seq)
    assert [f[0] for f in frames] == [float(stamp) for stamp, _ in listed]
    # 248 frames have a ground-truth pose within 20 ms (data README).
    poses = [gt for _, _, gt in frames if gt is not None]
    assert len(poses) == 248
    for gt in poses[:5]:
        assert gt.shape == (4, 4)
        np.testing.assert_allclose(gt[:3, :3] @ gt[:3, :3].T, np.eye(3), atol=1e-9)
    stamp, depth, _ = seq[-1]
    assert depth.dtype == np.uint16 and depth.shape == (480, 640)
    assert np.array_equal(depth, read_png(tum_dir / listed[-1][1]))
    with pytest.raises(IndexError):
        seq[252]


def test_bad_folders(tmp_path):
    with pytest.raises(OSError, match=str(tmp_path / "none")):
        planeslam.read_sequence(tmp_path / "none")
    (tmp_path / "seq").mkdir()
    (tmp_path / "seq" / "depth.txt").write_text("1.0 depth/1.0.png\n")
    seq = planeslam.read_sequence(tmp_path / "seq", sensor="none")
    assert len(seq) == 1 and seq.profile is None
    with pytest.raises(OSError, match="depth.txt:1: names 'depth/1.0.png' which does not exist"):
        seq[0]
