#!/usr/bin/env python3
"""Wall time of the nine-job batch (three simulated sequences x three variants) through GNU
parallel with --jobs 2 against the same nine `planeslam run`s one after another, measured in
interleaved rounds (plain loop, --jobs 2, --jobs 1, ...) so that a change in the machine's load
touches all three alike. Not part of ctest: it takes minutes.

Usage: measure_speedup.py PLANESLAM WORKDIR [--frames N] [--rounds R]"""
import argparse
import os
import pathlib
import shutil
import statistics
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import batch_test  # noqa: E402  (the same sequences, manifest and variants)


def timed(args):
    start = time.perf_counter()
    r = subprocess.run([str(a) for a in args], capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"failed: {' '.join(map(str, args))}\n{r.stdout}\n{r.stderr}")
    return time.perf_counter() - start


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("planeslam")
    parser.add_argument("work")
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--rounds", type=int, default=3)
    a = parser.parse_args()
    work = pathlib.Path(a.work)
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    batch_test.SMALL_CAMERA[:] = [f"simulation.frames={a.frames}"]  # full 640 x 480 frames
    batch_test.make_sequences(a.planeslam, work / "data")
    manifest = work / "nine.yaml"
    batch_test.write_manifest(manifest, ["data/" + s for s in batch_test.SCENES])
    print("load before:", os.getloadavg())
    rows = []
    for k in range(a.rounds):
        plain = 0.0
        for scene in batch_test.SCENES:
            for variant, overrides in batch_test.VARIANTS.items():
                args = [a.planeslam, "run", work / "data" / scene, "--out",
                        work / f"plain{k}" / scene / variant, "-q"]
                for key, v in {**batch_test.GLOBAL_SET, **overrides}.items():
                    args += ["--set", f"{key}={v}"]
                plain += timed(args)
        j2 = timed([a.planeslam, "batch", manifest, "--out", work / f"j2_{k}", "--jobs", "2"])
        j1 = timed([a.planeslam, "batch", manifest, "--out", work / f"j1_{k}", "--jobs", "1"])
        rows.append((plain, j2, j1))
        print(f"round {k + 1}: one after another {plain:.2f} s, --jobs 1 {j1:.2f} s, "
              f"--jobs 2 {j2:.2f} s: ratio --jobs 2 / one after another {j2 / plain:.3f}, "
              f"--jobs 2 / --jobs 1 {j2 / j1:.3f}  (load {os.getloadavg()[0]:.2f})", flush=True)
    ratios = [j2 / plain for plain, j2, _ in rows]
    print(f"median ratio --jobs 2 / one after another: {statistics.median(ratios):.3f} "
          f"(rounds: {', '.join(f'{r:.3f}' for r in ratios)})")


if __name__ == "__main__":
    main()
