#!/usr/bin/env python3
"""End-to-end tests of `planeslam batch`, driving the built executable.

Usage: batch_test.py MODE PLANESLAM WORKDIR, MODE one of
  manifest  the manifest format: the smallest form, sweeps, command lines, bad manifests;
  parallel  nine jobs (three short simulated sequences x three variants) through GNU parallel
            with --jobs 2: metrics equal to plain `planeslam run`s, collect's table equal to the
            jobs' metrics.json, a batch killed half-way and rerun, a corrupt sequence;
  slurm     the same nine jobs as a job array on a throwaway single-node Slurm cluster (munged,
            slurmctld, slurmd started here with every path inside WORKDIR, stopped by pid).
Exit 0 when every check passed, 1 when one failed, 77 (ctest: skipped) with the reason when the
mode cannot run here (GNU parallel or Slurm missing, the cluster does not start)."""
import csv
import json
import math
import os
import pathlib
import shutil
import signal
import socket
import subprocess
import sys
import time

SKIP = 77
FAILURES = []
PASSED = []


def dry_run_names(r):
    """The job names a `batch --dry-run` lists (one line per job, its command indented below)."""
    return [line.split(" ")[0] for line in r.stdout.splitlines()[1:] if not line.startswith(" ")]


def check(condition, message):
    print(("ok    " if condition else "FAIL  ") + message, flush=True)
    (PASSED if condition else FAILURES).append(message)
    return condition


def skip(reason):
    print("SKIPPED: " + reason, flush=True)
    sys.exit(SKIP)


def run(args, **kw):
    return subprocess.run([str(a) for a in args], capture_output=True, text=True, **kw)


# Three short sequences: 20 frames of each scene at 320 x 240.
SMALL_CAMERA = ["simulation.frames=20", "simulation_pinhole.width=320",
                "simulation_pinhole.height=240", "simulation_pinhole.fx=267.7",
                "simulation_pinhole.fy=269.6", "simulation_pinhole.cx=160",
                "simulation_pinhole.cy=124"]
SCENES = ["room", "corridor", "rubble"]
# The variants of the nine-job manifest and the overrides each amounts to (written out here, not
# taken from the batch, so that the plain runs are independent of it).
GLOBAL_SET = {"octomap.enabled": "false"}
VARIANTS = {"default": {}, "fast": {"detection.method": "grid-fast"},
            "decimated": {"run.decimation": "2"}}


def make_sequences(planeslam, data):
    data.mkdir(parents=True, exist_ok=True)
    for scene in SCENES:
        if (data / scene / "groundtruth.txt").exists():
            continue
        args = [planeslam, "simulate", scene, "--out", data / scene, "-q"]
        for s in SMALL_CAMERA:
            args += ["--set", s]
        r = run(args)
        if r.returncode != 0:
            print(r.stderr)
            sys.exit("cannot simulate " + scene)


def write_manifest(path, sequences):
    """`sequences`: folder paths, or (path, variant names) for a sequence run under those only."""
    lines = ["# three sequences x three variants", "sequences:"]
    for s in sequences:
        if isinstance(s, tuple):
            lines += [f"  - path: {s[0]}", f"    variants: [{', '.join(s[1])}]"]
        else:
            lines += ["  - path: " + s]
    lines += ["variants:", "  - name: default", "  - name: fast",
              "    set: {detection.method: grid-fast}",
              "  - name: decimated", "    set: {run.decimation: 2}",
              "set: {octomap.enabled: false}"]
    path.write_text("\n".join(lines) + "\n")


def read_json(path):
    with open(path) as f:
        return json.load(f)


def plain_references(planeslam, data, ref):
    """metrics.json and summary.json of a plain `planeslam run` per sequence and variant."""
    out = {}
    for scene in SCENES:
        for variant, overrides in VARIANTS.items():
            folder = ref / scene / variant
            if not (folder / "metrics.json").exists():
                args = [planeslam, "run", data / scene, "--out", folder, "-q"]
                for k, v in {**GLOBAL_SET, **overrides}.items():
                    args += ["--set", f"{k}={v}"]
                r = run(args)
                if r.returncode != 0:
                    print(r.stderr)
                    sys.exit(f"plain run of {scene}/{variant} failed")
            out[f"{scene}/{variant}"] = (read_json(folder / "metrics.json"),
                                         read_json(folder / "summary.json"))
    return out


def check_jobs_equal_references(out_dir, refs, names, what):
    for name in names:
        folder = out_dir / name
        if not check((folder / "metrics.json").exists(), f"{what}: {name} has metrics.json"):
            continue
        metrics, summary = read_json(folder / "metrics.json"), read_json(folder / "summary.json")
        ref_metrics, ref_summary = refs[name]
        check(metrics == ref_metrics, f"{what}: {name} metrics equal the plain planeslam run's")
        check(all(summary[k] == ref_summary[k] for k in ("frames", "keyframes", "loop_closures",
                                                          "map_planes")),
              f"{what}: {name} frames, keyframes, loop closures equal the plain run's")
        check(read_json(folder / "job.json")["status"] == "ok", f"{what}: {name} job.json ok")


def same_number(a, b):
    if a is None or b is None:
        return a is None and b is None
    return a == b or (math.isnan(a) and math.isnan(b))


def check_collect(planeslam, out_dir, complete_names, failed_names):
    r = run([planeslam, "batch", "collect", out_dir])
    check(r.returncode == 0, "collect exits 0: " + r.stderr.strip())
    results = read_json(out_dir / "results.json")
    rows = {f"{j['sequence']}/{j['variant']}": j for j in results["jobs"]}
    with open(out_dir / "results.csv") as f:
        csv_rows = {f"{row['sequence']}/{row['variant']}": row for row in csv.DictReader(f)}
    for name in complete_names:
        m = read_json(out_dir / name / "metrics.json")
        s = read_json(out_dir / name / "summary.json")
        expected = {"ate_rmse_m": m["ate"]["rmse"], "ate_mean_m": m["ate"]["mean"],
                    "ate_max_m": m["ate"]["max"],
                    "rpe_translation_rmse_m_per_frame": m["rpe_translation_m_per_frame"]["rmse"],
                    "rpe_rotation_rmse_deg_per_frame": m["rpe_rotation_deg_per_frame"]["rmse"],
                    "frames": s["frames"], "frames_per_second": s["frames_per_second"],
                    "keyframes": s["keyframes"], "loop_closures": s["loop_closures"]}
        row, csv_row = rows.get(name, {}), csv_rows.get(name, {})
        check(row.get("status") == "ok" and all(row.get(k) == v for k, v in expected.items()),
              f"collect: results.json figures of {name} equal its metrics.json/summary.json")
        check(all(float(csv_row.get(k, "nan")) == v for k, v in expected.items()),
              f"collect: results.csv figures of {name} equal its metrics.json/summary.json")
    for name in failed_names:
        row = rows.get(name, {})
        check(row.get("status") == "failed" and row.get("exit_code") == 2 and row.get("error"),
              f"collect: {name} marked failed with exit code 2 and its error: {row.get('error')}")
        check(row.get("ate_rmse_m") is None, f"collect: {name} has no figures")
    # Per variant: mean and worst over the sequences with figures.
    for v in results["variants"]:
        names = [n for n in complete_names if n.endswith("/" + v["variant"])]
        ates = [rows[n]["ate_rmse_m"] for n in names]
        if not ates:
            continue
        check(math.isclose(v["mean"]["ate_rmse_m"], sum(ates) / len(ates), rel_tol=1e-12) and
              v["worst"]["ate_rmse_m"] == max(ates) and v["jobs_with_figures"] == len(names),
              f"collect: variant {v['variant']} mean and worst ATE over {len(names)} sequences")
    md = (out_dir / "results.md").read_text()
    check(all(f"**{'failed'}**" in md for _ in failed_names), "collect: results.md marks failures")
    for svg in ("compare_ate.svg", "compare_rpe.svg", "compare_fps.svg"):
        text = (out_dir / svg).read_text() if (out_dir / svg).exists() else ""
        check(text.startswith("<?xml") and text.rstrip().endswith("</svg>"), f"collect: {svg}")


def processes_mentioning(text):
    found = []
    for p in pathlib.Path("/proc").iterdir():
        if not p.name.isdigit():
            continue
        try:
            cmdline = (p / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        if text in cmdline:
            found.append(int(p.name))
    return found


def complete_jobs(out_dir):
    return sorted(str(p.parent.relative_to(out_dir)) for p in out_dir.glob("*/*/job.json")
                  if not p.parent.name.startswith("."))


def test_kill_and_rerun(planeslam, manifest, out_dir, refs):
    """SIGKILL to the batch once some jobs finished: they stay intact, a rerun does the rest."""
    proc = subprocess.Popen([str(planeslam), "batch", str(manifest), "--out", str(out_dir),
                             "--jobs", "1"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            start_new_session=True)
    deadline = time.time() + 240
    while len(complete_jobs(out_dir)) < 3 and proc.poll() is None and time.time() < deadline:
        time.sleep(0.05)
    proc.kill()
    proc.wait()
    # What the batch had started stops on its own (parallel gets SIGTERM when the batch dies).
    deadline = time.time() + 60
    while processes_mentioning(str(out_dir)) and time.time() < deadline:
        time.sleep(0.1)
    check(not processes_mentioning(str(out_dir)), "kill: no job outlives the killed batch by 60 s")
    done = complete_jobs(out_dir)
    check(3 <= len(done) < 9, f"kill: the batch was killed half-way ({len(done)} of 9 complete)")
    check_jobs_equal_references(out_dir, refs, done, "kill: finished job intact")
    stamps = {n: os.stat(out_dir / n / "job.json").st_mtime_ns for n in done}
    r = run([planeslam, "batch", manifest, "--out", out_dir, "--jobs", "2"])
    check(r.returncode == 0, "rerun after the kill exits 0")
    check(f"{len(done)} complete, {9 - len(done)} to run" in r.stdout,
          f"rerun: {len(done)} complete, {9 - len(done)} to run")
    reran = [line.split(":")[0] for line in r.stdout.splitlines() if line.endswith(" s")]
    check(sorted(reran) == sorted(set(refs) - set(done)), "rerun runs exactly the missing jobs")
    check(all(os.stat(out_dir / n / "job.json").st_mtime_ns == t for n, t in stamps.items()),
          "rerun leaves the finished jobs untouched")
    check_jobs_equal_references(out_dir, refs, sorted(refs), "rerun")


def test_interrupt(planeslam, manifest, out_dir):
    """SIGINT to the batch: exit 130, finished jobs kept, the interrupted one recorded."""
    proc = subprocess.Popen([str(planeslam), "batch", str(manifest), "--out", str(out_dir),
                             "--jobs", "1"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, start_new_session=True)
    deadline = time.time() + 240
    while len(complete_jobs(out_dir)) < 2 and proc.poll() is None and time.time() < deadline:
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    out, _ = proc.communicate(timeout=120)
    check(proc.returncode == 130, f"SIGINT: the batch exits 130 (got {proc.returncode})")
    check("interrupted: finished jobs are kept" in out, "SIGINT: the batch says what it kept")
    done = complete_jobs(out_dir)
    check(2 <= len(done) < 9, f"SIGINT: {len(done)} finished jobs kept")


def test_corrupt_sequence(planeslam, data, work, refs):
    """Nine jobs, one of them on a sequence whose first frame is truncated: it fails with its
    error, the other eight complete (the last two sequences run under some variants only)."""
    broken = data / "broken"
    if not broken.exists():
        shutil.copytree(data / "rubble", broken)
        first = sorted((broken / "depth").glob("*.png"))[0]
        first.write_bytes(first.read_bytes()[:100])
    manifest = work / "corrupt.yaml"
    write_manifest(manifest, ["data/room", "data/corridor", ("data/rubble", ["default", "fast"]),
                              ("data/broken", ["default"])])
    out_dir = work / "corrupt"
    r = run([planeslam, "batch", manifest, "--out", out_dir, "--jobs", "2"])
    check(r.returncode == 2, f"corrupt sequence: the batch exits 2 (got {r.returncode})")
    check("planeslam batch: 9 jobs" in r.stdout, "corrupt sequence: nine jobs")
    good = [f"{s}/{v}" for s in ("room", "corridor") for v in VARIANTS] + ["rubble/default",
                                                                          "rubble/fast"]
    bad = ["broken/default"]
    check(sorted(complete_jobs(out_dir)) == sorted(good), "corrupt sequence: the other eight complete")
    check("8 of 9 jobs complete" in r.stdout, "corrupt sequence: the batch says 8 of 9 complete")
    check_jobs_equal_references(out_dir, refs, good, "corrupt sequence: other job")
    for name in bad:
        check(not (out_dir / name).exists(), f"corrupt sequence: no folder {name}")
        rec = out_dir / ".batch" / "failed" / name / "job.json"
        j = read_json(rec) if rec.exists() else {}
        check(j.get("exit_code") == 2 and ".png" in j.get("error", ""),
              f"corrupt sequence: {name} recorded with exit 2 and the bad file: {j.get('error')}")
        check(f"{name}: failed (exit 2)" in r.stdout, f"corrupt sequence: the batch lists {name}")
    check_collect(planeslam, out_dir, good, bad)
    rows = {f"{j['sequence']}/{j['variant']}": j for j in read_json(out_dir / "results.json")["jobs"]}
    md = (out_dir / "results.md").read_text()
    for name in bad:
        error = read_json(out_dir / ".batch" / "failed" / name / "job.json").get("error", "")
        check(bool(error) and error in rows.get(name, {}).get("error", "") and error in md,
              f"collect: {name}'s row holds its error line (results.json, results.md): {error}")


def test_outdated(planeslam, manifest, out_dir):
    """A variant whose settings changed: its jobs are outdated and rerun, the others kept."""
    text = manifest.read_text()
    manifest.write_text(text.replace("run.decimation: 2", "run.decimation: 3"))
    stamps = {n: os.stat(out_dir / n / "job.json").st_mtime_ns for n in complete_jobs(out_dir)}
    r = run([planeslam, "batch", manifest, "--out", out_dir, "--dry-run"])
    outdated = sorted(line.split(" ")[0] for line in r.stdout.splitlines() if "[outdated]" in line)
    check(outdated == [f"{s}/decimated" for s in sorted(SCENES)],
          f"changed settings: the variant's jobs are outdated: {outdated}")
    r = run([planeslam, "batch", manifest, "--out", out_dir, "--jobs", "2"])
    check(r.returncode == 0 and "6 complete, 3 to run" in r.stdout, "changed settings: 3 rerun")
    kept = [n for n in stamps if not n.endswith("/decimated")]
    check(all(os.stat(out_dir / n / "job.json").st_mtime_ns == stamps[n] for n in kept),
          "changed settings: the other six untouched")
    check(all(read_json(out_dir / f"{s}/decimated/job.json")["args"][-1] == "run.decimation=3"
              for s in SCENES), "changed settings: the rerun jobs hold the new settings")
    manifest.write_text(text)


def test_time_limit(planeslam, work):
    """A job over its time limit is stopped, recorded as timed out, and keeps no folder."""
    manifest = work / "slow.yaml"
    manifest.write_text("sequences:\n  - scene: rubble\nset: {octomap.enabled: false}\n"
                        "time_limit: '0:02'\n")
    out_dir = work / "slow"
    start = time.time()
    r = run([planeslam, "batch", manifest, "--out", out_dir, "--jobs", "1"])
    rec = out_dir / ".batch" / "failed" / "rubble" / "default" / "job.json"
    j = read_json(rec) if rec.exists() else {}
    check(r.returncode == 2 and j.get("status") == "timed_out" and
          "time limit of 2 s exceeded" in j.get("error", "") and not (out_dir / "rubble/default").exists(),
          f"time limit: stopped after 2 s and recorded ({time.time() - start:.1f} s): {j.get('error')}")


def mode_parallel(planeslam, work):
    if not shutil.which("parallel"):
        skip("GNU parallel is not installed (Debian package parallel)")
    data = work / "data"
    make_sequences(planeslam, data)
    refs = plain_references(planeslam, data, work / "plain")
    manifest = work / "nine.yaml"
    write_manifest(manifest, ["data/" + s for s in SCENES])
    out_dir = work / "nine"
    shutil.rmtree(out_dir, ignore_errors=True)
    r = run([planeslam, "batch", manifest, "--out", out_dir, "--jobs", "2"])
    check(r.returncode == 0, "nine jobs through GNU parallel --jobs 2 exit 0: " + r.stderr.strip())
    check_jobs_equal_references(out_dir, refs, sorted(refs), "parallel")
    check_collect(planeslam, out_dir, sorted(refs), [])
    r = run([planeslam, "batch", manifest, "--out", out_dir, "--jobs", "2"])
    check(r.returncode == 0 and "9 complete, 0 to run" in r.stdout,
          "a second run of a complete batch runs nothing")
    test_outdated(planeslam, manifest, out_dir)
    test_time_limit(planeslam, work)
    test_kill_and_rerun(planeslam, manifest, work / "killed", refs)
    test_interrupt(planeslam, manifest, work / "interrupted")
    test_corrupt_sequence(planeslam, data, work, refs)


def mode_manifest(planeslam, work):
    work.mkdir(parents=True, exist_ok=True)
    for s in ("room", "corridor"):
        (work / s).mkdir(exist_ok=True)
    smallest = work / "smallest.yaml"
    smallest.write_text("sequences:\n  - path: room\n  - path: corridor\nvariants:\n"
                        "  - name: default\n  - name: fast\n"
                        "    set: {detection.method: grid-fast}\n")
    r = run([planeslam, "batch", smallest, "--out", work / "o", "--dry-run"])
    check(r.returncode == 0, "smallest manifest: dry run exits 0: " + r.stderr.strip())
    names = dry_run_names(r)
    check(names == ["room/default", "room/fast", "corridor/default", "corridor/fast"],
          f"smallest manifest: four jobs <sequence>/<variant>: {names}")
    check(f"run {work / 'room'} --set detection.method=grid-fast --out {work / 'o' / 'room' / 'fast'}"
          in r.stdout, "smallest manifest: the exact planeslam run command line")
    check(not (work / "o").exists(), "dry run writes nothing")

    sweep = work / "sweep.yaml"
    sweep.write_text("sequences:\n  - {path: room, name: r1, set: {run.max_frames: 5}}\n"
                     "  - {scene: rubble}\n"
                     "variants:\n  - name: t\n    set: {detection.method: grid}\n"
                     "    sweep: {detection.theta: [200, 800], grid.cell_size: [3, 6]}\n"
                     "set: {octomap.enabled: false}\ntime_limit: '1:30'\n")
    r = run([planeslam, "batch", sweep, "--out", work / "o", "--dry-run"])
    names = dry_run_names(r)
    expected = [f"{s}/t+detection.theta={t}+grid.cell_size={c}" for s in ("r1", "rubble")
                for t in (200, 800) for c in (3, 6)]
    check(r.returncode == 0 and names == expected, f"sweep: 2 x 2 values x 2 sequences: {names}")
    check("run --scene rubble --set octomap.enabled=false --set detection.method=grid "
          "--set detection.theta=800 --set grid.cell_size=6" in r.stdout,
          "sweep: overrides in order global, sequence, variant, sweep")
    check("--set run.max_frames=5 --set detection.method=grid" in r.stdout,
          "sweep: a sequence's own overrides")

    subset = work / "subset.yaml"
    subset.write_text("sequences:\n  - path: room\n  - {path: corridor, variants: fast}\n"
                      "  - {scene: rubble, variants: [default, t]}\n"
                      "variants:\n  - name: default\n  - name: fast\n"
                      "    set: {detection.method: grid-fast}\n"
                      "  - name: t\n    sweep: {detection.theta: [200, 800]}\n")
    r = run([planeslam, "batch", subset, "--out", work / "o", "--dry-run"])
    names = dry_run_names(r)
    expected = ["room/default", "room/fast", "room/t+detection.theta=200",
                "room/t+detection.theta=800", "corridor/fast", "rubble/default",
                "rubble/t+detection.theta=200", "rubble/t+detection.theta=800"]
    check(r.returncode == 0 and names == expected,
          f"a sequence under some variants only (a name selects its whole sweep): {names}")

    bad_cases = {
        "unknown variant of a sequence": ("sequences:\n  - {path: room, variants: [b]}\n"
                                          "variants:\n  - name: a\n",
                                          ":2: no variant named 'b' (variants: a)"),
        "unknown key": ("sequences:\n  - path: room\nvariant:\n  - name: a\n", ":3: unknown key 'variant'"),
        "missing sequence": ("sequences:\n  - path: nowhere\n", ":2: sequence "),
        "duplicate variant": ("sequences:\n  - path: room\nvariants:\n  - name: a\n  - name: a\n",
                              "two variants are named a"),
        "bad override": ("sequences:\n  - path: room\nvariants:\n  - name: a\n"
                         "    set: {detection.metod: grid}\n", "job room/a"),
        "bad name": ("sequences:\n  - {path: room, name: 'a b'}\n", "must be letters"),
        "not yaml": ("sequences: [\n", "not valid YAML"),
    }
    for what, (text, expected) in bad_cases.items():
        path = work / "bad.yaml"
        path.write_text(text)
        r = run([planeslam, "batch", path, "--out", work / "o", "--dry-run"])
        lines = r.stderr.strip().splitlines()
        check(r.returncode == 2 and len(lines) == 1 and str(path) in lines[0] and
              expected in lines[0], f"bad manifest ({what}): one line naming it: {r.stderr.strip()}")
    r = run([planeslam, "batch", "collect", work / "nothing"])
    check(r.returncode == 2 and "not the output folder of a planeslam batch" in r.stderr,
          "collect of a folder that is no batch: " + r.stderr.strip())


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class SlurmCluster:
    """munged, slurmctld and slurmd on this machine, every file under `root`."""

    def __init__(self, root):
        self.root = root
        self.procs = []
        self.env = dict(os.environ, SLURM_CONF=str(root / "slurm.conf"))

    def start(self):
        for tool in ("munged", "slurmctld", "slurmd", "sbatch", "scancel", "sinfo"):
            if not shutil.which(tool):
                skip(f"{tool} is not installed (Debian packages slurm-wlm and munge)")
        if os.geteuid() != 0:
            skip("slurmd needs root to start jobs as the submitting user")
        root = self.root
        shutil.rmtree(root, ignore_errors=True)
        for d, mode in (("sock", 0o711), ("key", 0o700), ("log", 0o700), ("state", 0o700),
                        ("spool", 0o700)):
            (root / d).mkdir(parents=True)
            os.chmod(root / d, mode)
        key = root / "key" / "munge.key"
        key.write_bytes(os.urandom(1024))
        os.chmod(key, 0o400)
        socket_path = root / "sock" / "munge.socket"
        self.spawn(["munged", "--foreground", "--force", f"--socket={socket_path}",
                    f"--key-file={key}", f"--log-file={root / 'log' / 'munged.log'}",
                    f"--pid-file={root / 'log' / 'munged.pid'}",
                    f"--seed-file={root / 'state' / 'munged.seed'}"], "munged")
        host = socket.gethostname().split(".")[0]
        cpus = os.cpu_count() or 1
        with open("/proc/meminfo") as f:
            mem_mb = int(f.readline().split()[1]) // 1024 // 2
        log = root / "log"
        (root / "slurm.conf").write_text(f"""ClusterName=planeslamtest
SlurmctldHost={host}(127.0.0.1)
SlurmctldPort={free_port()}
SlurmdPort={free_port()}
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket={socket_path}
SlurmUser=root
SlurmdUser=root
StateSaveLocation={root / 'state'}
SlurmdSpoolDir={root / 'spool'}
SlurmctldPidFile={log / 'slurmctld.pid'}
SlurmdPidFile={log / 'slurmd.pid'}
SlurmctldLogFile={log / 'slurmctld.log'}
SlurmdLogFile={log / 'slurmd.log'}
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SchedulerType=sched/builtin
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
ReturnToService=2
MpiDefault=none
JobCompType=jobcomp/none
AccountingStorageType=accounting_storage/none
NodeName={host} NodeAddr=127.0.0.1 CPUs={cpus} RealMemory={mem_mb} State=UNKNOWN
PartitionName=test Nodes={host} Default=YES MaxTime=INFINITE State=UP
""")
        time.sleep(0.5)
        self.spawn(["slurmctld", "-D", "-f", root / "slurm.conf"], "slurmctld")
        self.spawn(["slurmd", "-D", "-N", host, "-f", root / "slurm.conf"], "slurmd")
        deadline = time.time() + 30
        while time.time() < deadline:
            r = run(["sinfo", "-h", "-o", "%T"], env=self.env)
            if r.returncode == 0 and r.stdout.strip() in ("idle", "mixed", "allocated"):
                print(f"Slurm cluster up: node {host}, {cpus} CPUs, state {r.stdout.strip()}")
                return
            if any(p.poll() is not None for p, _ in self.procs):
                break
            time.sleep(0.5)
        logs = "; ".join(f"{n}: " + (log / f"{n}.out").read_text().strip()[-300:]
                         for _, n in self.procs)
        self.stop()
        skip("the single-node Slurm cluster did not start within 30 s (" + logs + ")")

    def spawn(self, args, name):
        out = open(self.root / "log" / f"{name}.out", "w")
        self.procs.append((subprocess.Popen([str(a) for a in args], stdout=out,
                                            stderr=subprocess.STDOUT, env=self.env,
                                            start_new_session=True), name))

    def stop(self):
        # Jobs first, or their steps outlive the daemons; then the daemons by pid, newest first.
        if any(n == "slurmctld" and p.poll() is None for p, n in self.procs):
            run(["scancel", "--user", str(os.getuid())], env=self.env)
            deadline = time.time() + 20
            while time.time() < deadline:
                r = run(["squeue", "-h"], env=self.env)
                if r.returncode != 0 or not r.stdout.strip():
                    break
                time.sleep(0.5)
        for p, _ in reversed(self.procs):
            if p.poll() is None:
                p.terminate()
            try:
                p.wait(timeout=15)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        self.procs = []


def mode_slurm(planeslam, work):
    data = work / "data"
    cluster = SlurmCluster(work / "cluster")
    cluster.start()
    try:
        make_sequences(planeslam, data)
        refs = plain_references(planeslam, data, work / "plain")
        manifest = work / "nine.yaml"
        write_manifest(manifest, ["data/" + s for s in SCENES])
        out_dir = work / "nine"
        shutil.rmtree(out_dir, ignore_errors=True)
        r = run([planeslam, "batch", manifest, "--out", out_dir, "--slurm", "--print"])
        script = out_dir / ".batch" / "slurm" / "batch.sbatch"
        check(r.returncode == 0 and script.exists() and "#SBATCH --array=0-8" in r.stdout,
              "--slurm --print writes the job-array script")
        check(not complete_jobs(out_dir), "--slurm --print runs nothing")
        r = run([planeslam, "batch", manifest, "--out", out_dir, "--slurm", "--wait",
                 "--time-limit", "10"], env=cluster.env, timeout=900)
        print(r.stdout + r.stderr)
        check(r.returncode == 0, "the nine jobs as a Slurm job array (sbatch --wait) exit 0")
        text = script.read_text()
        check("#SBATCH --time=0-00:10:00" in text, "the time limit reaches the script")
        check_jobs_equal_references(out_dir, refs, sorted(refs), "slurm")
        logs = list((out_dir / ".batch" / "slurm").glob("*_*.log"))
        check(len(logs) == 9, f"one Slurm log per array task ({len(logs)})")
        check(all((out_dir / n / "stderr.log").exists() and (out_dir / n / "stdout.log").exists()
                  for n in refs), "each job's stdout and stderr in its folder")
        check_collect(planeslam, out_dir, sorted(refs), [])
    finally:
        cluster.stop()


def main():
    if len(sys.argv) != 4 or sys.argv[1] not in ("manifest", "parallel", "slurm"):
        sys.exit(__doc__)
    mode, planeslam, work = sys.argv[1], pathlib.Path(sys.argv[2]), pathlib.Path(sys.argv[3])
    shutil.rmtree(work, ignore_errors=True)  # sequences and references from this build only
    work.mkdir(parents=True)
    start = time.time()
    {"manifest": mode_manifest, "parallel": mode_parallel, "slurm": mode_slurm}[mode](planeslam, work)
    print(f"batch {mode} ({time.time() - start:.1f} s): {len(PASSED)} passed, {len(FAILURES)} failed")
    sys.exit(1 if FAILURES else 0)


if __name__ == "__main__":
    main()
