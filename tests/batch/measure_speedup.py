#!/usr/bin/env python3
"""Wall time of the nine-job batch (three simulated sequences x three variants) through GNU
parallel with --jobs 2 against the same nine `planeslam run`s one after another (each with the
threads a job of --jobs 2 gets, the same command line; and, for reference, on all cores), measured in
interleaved rounds (one after another, two at a time, --jobs 2, --jobs 1, ...) so that a change in
the machine's load touches all of them alike. "Two at a time" starts the same plain runs from
here, two at once: the best any dispatcher can do on this machine at that moment, so --jobs 2
against it is the batch's own cost. From GNU parallel's joblog: the batch's start (batch start to
its first job's start), its end (last job's end to the batch's exit) and the mean gap between a
job's end and the next job's start. Not part of ctest: it takes minutes.

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


def plain_commands(planeslam, work, out, threads=None):
    """The nine plain runs; `threads` as each job of `--jobs 2` runs them (None: all cores)."""
    commands = []
    for scene in batch_test.SCENES:
        for variant, overrides in batch_test.VARIANTS.items():
            args = [planeslam, "run", work / "data" / scene, "--out", out / scene / variant, "-q"]
            if threads is not None:
                args += ["--threads", threads]
            for key, v in {**batch_test.GLOBAL_SET, **overrides}.items():
                args += ["--set", f"{key}={v}"]
            commands.append([str(a) for a in args])
    return commands


def run_at_most(commands, at_once):
    """Runs `commands`, at most `at_once` at a time; returns the wall time."""
    start = time.perf_counter()
    running, queue = [], list(commands)
    while queue or running:
        while queue and len(running) < at_once:
            running.append(subprocess.Popen(queue.pop(0), stdout=subprocess.DEVNULL,
                                            stderr=subprocess.DEVNULL))
        pid, status = os.wait()
        if status != 0:
            sys.exit(f"a plain run failed (status {status})")
        running = [p for p in running if p.pid != pid]
    return time.perf_counter() - start


def timed_batch(planeslam, manifest, out, jobs):
    """Wall time of the batch and its engine's timeline from GNU parallel's joblog."""
    start_epoch = time.time()
    start = time.perf_counter()
    r = subprocess.run([str(planeslam), "batch", str(manifest), "--out", str(out), "--jobs",
                        str(jobs)], capture_output=True, text=True)
    wall = time.perf_counter() - start
    end_epoch = time.time()
    if r.returncode != 0:
        sys.exit(f"batch failed:\n{r.stdout}\n{r.stderr}")
    rows = []
    for line in (out / ".batch" / "parallel.joblog").read_text().splitlines()[1:]:
        f = line.split("\t")
        rows.append((float(f[2]), float(f[2]) + float(f[3])))
    rows.sort()
    ends = sorted(e for _, e in rows)
    # Each job after the first `jobs` starts when a slot frees: its gap is to the latest job end
    # before its start.
    gaps = []
    for s, _ in rows[jobs:]:
        before = [e for e in ends if e <= s + 1e-3]
        if before:
            gaps.append(s - before[-1])
    return wall, rows[0][0] - start_epoch, end_epoch - ends[-1], statistics.mean(gaps) if gaps else 0.0


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
    print(f"{os.cpu_count()} cores; load before: {os.getloadavg()}")
    rows = []
    for k in range(a.rounds):
        load = os.getloadavg()[0]
        cores = os.cpu_count()
        share = max(1, cores // 2)  # the threads `--jobs 2` gives each job
        plain = run_at_most(plain_commands(a.planeslam, work, work / f"plain{k}", share), 1)
        plain_all = run_at_most(plain_commands(a.planeslam, work, work / f"all{k}"), 1)
        pairs = run_at_most(plain_commands(a.planeslam, work, work / f"pairs{k}", share), 2)
        j2, j2_start, j2_end, j2_gap = timed_batch(a.planeslam, manifest, work / f"j2_{k}", 2)
        j1, _, _, j1_gap = timed_batch(a.planeslam, manifest, work / f"j1_{k}", 1)
        rows.append((plain, pairs, j2, j1, plain_all))
        print(f"round {k + 1} (load {load:.1f}): one after another {plain:.2f} s, two at a time "
              f"{pairs:.2f} s, --jobs 2 {j2:.2f} s, --jobs 1 {j1:.2f} s; --jobs 2 / one after "
              f"another {j2 / plain:.3f}, two at a time / one after another {pairs / plain:.3f}, "
              f"--jobs 2 / two at a time {j2 / pairs:.3f}; --jobs 2: start {j2_start:.3f} s, end "
              f"{j2_end:.3f} s, gap {1000 * j2_gap:.0f} ms; --jobs 1 gap {1000 * j1_gap:.0f} ms; "
              f"one after another on all cores {plain_all:.2f} s, --jobs 2 / that "
              f"{j2 / plain_all:.3f}",
              flush=True)
    print(f"load after: {os.getloadavg()}")
    for label, i, j in (("--jobs 2 / one after another", 2, 0),
                        ("two at a time / one after another", 1, 0),
                        ("--jobs 2 / two at a time", 2, 1), ("--jobs 1 / one after another", 3, 0),
                        ("--jobs 2 / one after another on all cores", 2, 4)):
        ratios = [r[i] / r[j] for r in rows]
        print(f"median {label}: {statistics.median(ratios):.3f} "
              f"(rounds: {', '.join(f'{x:.3f}' for x in ratios)})")


if __name__ == "__main__":
    main()
