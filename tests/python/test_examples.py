"""examples/python/*.py run as a user would run them (the README quotes them verbatim)."""
import os
import subprocess
import sys

import planeslam
from conftest import SOURCE_DIR


def test_detect_tum_example(tum_dir):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    done = subprocess.run([sys.executable, SOURCE_DIR / "examples" / "python" / "detect_tum.py",
                           tum_dir], capture_output=True, text=True, env=env)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    seq = planeslam.read_sequence(tum_dir)
    stamp, depth, _ = seq[0]
    result = planeslam.detect(depth, seq.intrinsics, sensor="tum-fr3")
    assert lines[0] == f"grid3: {len(result.planes)} planes at t = {stamp:.6f}"
    assert len(lines) == 1 + len(result.planes)
    assert lines[1].startswith("plane 1: n = [") and lines[1].endswith(f"{result.planes[0].points} px")
