"""Shared fixtures of the Python module's tests: the real data, the planeslam executable (the
CLI whose outputs the module must reproduce) and a small PNG reader for its label images."""
import os
import pathlib
import struct
import subprocess
import zlib

import numpy as np
import pytest

SOURCE_DIR = pathlib.Path(__file__).resolve().parents[2]


def data_dir():
    """PLANESLAM_DATA_DIR, else ../shared/data beside the source tree (as the C++ tests)."""
    env = os.environ.get("PLANESLAM_DATA_DIR")
    return pathlib.Path(env) if env else (SOURCE_DIR.parent / "shared" / "data").resolve()


def require_data(*parts):
    path = data_dir().joinpath(*parts)
    if not path.exists():
        pytest.skip(f"real data not found: {path} (set PLANESLAM_DATA_DIR)")
    return path


@pytest.fixture
def tum_dir():
    return require_data("tum_fr3_structure_notexture_far")


@pytest.fixture
def trajectories_dir():
    return require_data("trajectories")


@pytest.fixture
def cli():
    """Runs the planeslam executable (PLANESLAM_BIN, set by ctest) and returns its stdout."""
    exe = os.environ.get("PLANESLAM_BIN")
    if not exe or not os.path.exists(exe):
        pytest.skip("PLANESLAM_BIN does not name the planeslam executable (run through ctest)")

    def run(*args):
        done = subprocess.run([exe, *map(str, args)], capture_output=True, text=True)
        assert done.returncode == 0, f"planeslam {' '.join(map(str, args))}: {done.stderr}"
        return done.stdout

    return run


def read_png(path):
    """A non-interlaced greyscale or RGB PNG (8 or 16 bit) as a numpy array."""
    data = pathlib.Path(path).read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", f"{path}: not a PNG"
    pos, idat, header = 8, b"", None
    while pos < len(data):
        length, kind = struct.unpack(">I4s", data[pos:pos + 8])
        chunk = data[pos + 8:pos + 8 + length]
        if kind == b"IHDR":
            header = struct.unpack(">IIBBBBB", chunk)
        elif kind == b"IDAT":
            idat += chunk
        pos += 12 + length
    width, height, depth, colour, _, _, interlace = header
    assert interlace == 0 and colour in (0, 2) and depth in (8, 16)
    channels = 3 if colour == 2 else 1
    bpp = channels * depth // 8
    stride = width * bpp
    raw = zlib.decompress(idat)
    rows, prev = [], [0] * stride
    for y in range(height):
        start = y * (stride + 1)
        kind, line = raw[start], raw[start + 1:start + 1 + stride]
        if kind == 0:
            cur = list(line)
        elif kind == 2:
            cur = [(v + b) & 0xFF for v, b in zip(line, prev)]
        else:
            cur = [0] * stride
            for x in range(stride):
                a = cur[x - bpp] if x >= bpp else 0
                if kind == 1:
                    pred = a
                elif kind == 3:
                    pred = (a + prev[x]) >> 1
                else:  # Paeth
                    b, c = prev[x], (prev[x - bpp] if x >= bpp else 0)
                    p = a + b - c
                    pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                    pred = a if pa <= pb and pa <= pc else (b if pb <= pc else c)
                cur[x] = (line[x] + pred) & 0xFF
        rows.append(cur)
        prev = cur
    out = np.array(rows, dtype=np.uint8)
    if depth == 16:
        img = out.reshape(height, width * channels, 2).astype(np.uint16)
        img = (img[..., 0] << 8) | img[..., 1]
    else:
        img = out
    return img.reshape(height, width, channels) if channels == 3 else img.reshape(height, width)
