#!/usr/bin/env python3
"""Overhead of planeslam.detect over the C++ work it wraps, on one 640x480 uint16 TUM frame:
the median of N calls of planeslam.detect (timed in Python) against the median of N runs of the
same C++ work (back-projection, detection, label image) timed inside C++ by
planeslam._bench_detect_cpp, interleaved in one process. Not a test: timings vary with load.

  PYTHONPATH=build/python python3 tests/python/bench_detect_overhead.py DATA/tum_fr3_... [N]"""
import statistics
import sys
import time

import planeslam


def main():
    folder = sys.argv[1]
    n = int(sys.argv[2]) if len(sys.argv) > 2 else 50
    seq = planeslam.read_sequence(folder)
    _, depth, _ = seq[0]
    args = dict(intrinsics=seq.intrinsics, depth_scale=seq.depth_scale, sensor=seq.profile)
    for method in ("grid", "grid-fast", "point"):
        planeslam.detect(depth, method=method, **args)  # warm-up
        py_ms, cpp_ms = [], []
        for _ in range(5):  # interleaved rounds, so a change of machine load hits both sides
            for _ in range(n // 5):
                t = time.perf_counter()
                planeslam.detect(depth, method=method, **args)
                py_ms.append(1000.0 * (time.perf_counter() - t))
            cpp_ms += planeslam._bench_detect_cpp(depth, method=method, repeats=n // 5,
                                                  **args)["times_ms"]
        py, cpp = statistics.median(py_ms), statistics.median(cpp_ms)
        print(f"{method:10s} planeslam.detect {py:7.3f} ms  C++ {cpp:7.3f} ms  "
              f"overhead {100.0 * (py / cpp - 1.0):+5.1f} %  (median of {len(py_ms)} each)")


if __name__ == "__main__":
    main()
