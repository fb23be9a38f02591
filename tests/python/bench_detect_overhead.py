#!/usr/bin/env python3
"""Overhead of planeslam.detect over the C++ work it wraps (back-projection, detection, label
image), on the first 640x480 uint16 frame of a TUM folder, with the folder's profile. Not a test.

Timed, in one process: the median of N calls of planeslam.detect (timed in Python) against the
median of N runs of the same C++ work timed inside C++ by planeslam._bench_detect_cpp,
interleaved in rounds so a change of machine load hits both sides:
  PYTHONPATH=build/python python3 tests/python/bench_detect_overhead.py FOLDER [N]

Counted (independent of load): run once with K and once with K + 5 calls under callgrind, for
both sides; the difference / 5 is the instructions of one call:
  valgrind --tool=callgrind python3 tests/python/bench_detect_overhead.py FOLDER --count py K
  valgrind --tool=callgrind python3 tests/python/bench_detect_overhead.py FOLDER --count cpp K"""
import statistics
import sys
import time

import planeslam


def main():
    folder = sys.argv[1]
    seq = planeslam.read_sequence(folder)
    _, depth, _ = seq[0]
    args = dict(intrinsics=seq.intrinsics, depth_scale=seq.depth_scale, sensor=seq.profile)
    planeslam.detect(depth, **args)  # builds and keeps the detector, as a C++ caller would
    if len(sys.argv) > 2 and sys.argv[2] == "--count":
        side, k = sys.argv[3], int(sys.argv[4])
        if side == "py":
            for _ in range(k):
                planeslam.detect(depth, **args)
        else:
            planeslam._bench_detect_cpp(depth, repeats=k, **args)
        return
    n = int(sys.argv[2]) if len(sys.argv) > 2 else 50
    for method in ("grid", "grid-fast", "point"):
        planeslam.detect(depth, method=method, **args)  # warm-up
        py_ms, cpp_ms = [], []
        for _ in range(5):
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
