#!/usr/bin/env python3
"""Prints the headline figures of a measure_results.sh output folder (docs/RESULTS.md's tables).

Usage: headline.py OUT_DIR"""
import json
import pathlib
import re
import statistics
import sys

# The TUM tools' values for the shared trajectories (../shared/data/README.md).
EVAL_REFERENCE = {
    "eval_fr1_ate": {"compared_pose_pairs": "786", "absolute_translational_error.rmse": "0.013473"},
    "eval_fr2_ate": {"compared_pose_pairs": "2223", "absolute_translational_error.rmse": "0.008144"},
    "eval_fr1_rpe": {"compared_pose_pairs": "753", "translational_error.rmse": "0.021217",
                     "rotational_error.rmse": "0.934480"},
}


def load(out, name):
    path = out / name
    return json.loads(path.read_text()) if path.exists() else None


def is_vga(record):
    return (record["width"], record["height"]) == (640, 480)


def ratios(records, method):
    """Median over frames of PCL's time / the method's, on all frames and on the 640 x 480 ones."""
    rows = [r for r in records if r["method"] == method]
    return (statistics.median(r["speedup_vs_pcl"] for r in rows),
            statistics.median(r["speedup_vs_pcl"] for r in rows if is_vga(r)))


def detect_speed(out):
    runs = [json.loads(p.read_text()) for p in sorted(out.glob("detect_speed_[0-9].json"))]
    if not runs:
        return
    first = runs[0]
    methods = [m for m in dict.fromkeys(r["method"] for r in first) if m != "pcl_omps"]
    frames = len({r["frame"] for r in first})
    vga = len({r["frame"] for r in first if is_vga(r)})
    pcl = [statistics.median(r["median_ms"] for r in run if r["method"] == "pcl_omps")
           for run in runs]
    print(f"detection speed: {len(runs)} runs of {frames} frames ({vga} of 640 x 480); PCL OMPS "
          f"{min(pcl):.1f}-{max(pcl):.1f} ms a frame (median over frames)")
    print(f"  {'method':12} {'x PCL, all frames':>22} {'x PCL, 640 x 480':>22} {'planes':>7} "
          f"{'assigned':>9}")
    for m in methods:
        both = [ratios(run, m) for run in runs]
        rows = [r for r in first if r["method"] == m]
        planes = statistics.median(r["planes"] for r in rows)
        assigned = statistics.median(r["assigned_fraction"] for r in rows)
        cells = []
        for values in zip(*both):
            cells.append(f"{statistics.median(values):.1f}x ({min(values):.1f}-{max(values):.1f})")
        print(f"  {m:12} {cells[0]:>22} {cells[1]:>22} {planes:7.1f} {100 * assigned:8.1f}%")
    for p in sorted(out.glob("detect_speed_grid*.json")):
        records = json.loads(p.read_text())
        name = next(r["method"] for r in records if r["method"] != "pcl_omps")
        rows = [r for r in records if r["method"] == name]
        all_ratio, vga_ratio = ratios(records, name)
        label = f"{name} k={p.stem[len('detect_speed_grid'):]}"
        print(f"  {label:12} {all_ratio:>21.1f}x {vga_ratio:>21.1f}x "
              f"{statistics.median(r['planes'] for r in rows):7.1f} "
              f"{100 * statistics.median(r['assigned_fraction'] for r in rows):8.1f}%  (own run)")


def quality(out):
    synthetic = load(out, "quality_synthetic.json") or []
    tum = load(out, "quality_tum.json") or []
    if synthetic:
        print("detection quality, synthetic scenes with sensor noise (correct detections of large "
              "planes; mean / max normal error of correct ones)")
        for r in synthetic:
            if r["kind"] != "segmentation":
                continue
            error = "-" if r["correct"] == 0 else \
                f"{r['normal_error_mean_deg']:.3f} / {r['normal_error_max_deg']:.2f} deg"
            print(f"  {r['dataset']:18} {r['method']:10} {100 * r['correct_rate']:6.1f}%  "
                  f"{error:18} F1 {r['f1']:.3f}  pixacc {r['pixel_accuracy']:.3f}")
    if tum:
        print("plane repeatability, TUM fr3 (median angle / offset of matched large planes, "
              "share of large planes matched)")
        for r in tum:
            if r["kind"] != "repeatability":
                continue
            print(f"  {r['dataset']:10} {r['method']:10} {r['median_angle_deg']:.3f} deg / "
                  f"{100 * r['median_offset_m']:.3f} cm / {100 * r['matching_fraction']:.1f}% "
                  f"({r['matched_pairs']} pairs)")


def odometry(out):
    runs = load(out, "odometry_tum.json")
    if not runs:
        return
    print("odometry, TUM fr3 frame to frame (RPE rmse at 1 frame and 1 s; drift first to last)")
    for r, ate_file in zip(runs, ("planes", "gicp")):
        f, s = r.get("rpe_1_frame", {}), r.get("rpe_1_s", {})
        drift = sum(x * x for x in r.get("drift_world_m", [0, 0, 0])) ** 0.5
        ate = ate_of(out / f"odometry_ate_{ate_file}.txt")
        print(f"  {r['method']:16} {100 * f.get('trans_rmse_m', 0):.2f} cm / "
              f"{f.get('rot_rmse_deg', 0):.3f} deg, {100 * s.get('trans_rmse_m', 0):.2f} cm / "
              f"{s.get('rot_rmse_deg', 0):.3f} deg, drift {100 * drift:.2f} cm, ATE {ate}, "
              f"{r['median_ms']:.2f} ms/frame")
    if len(runs) == 2:
        print(f"  speed ratio GICP / ours: {runs[1]['median_ms'] / runs[0]['median_ms']:.1f}x")


def ate_of(path):
    if not path.exists():
        return "-"
    m = re.search(r"^\s*rmse\s+([0-9.]+)", path.read_text(), re.M)
    return f"{100 * float(m.group(1)):.2f} cm" if m else "-"


def slam(out):
    print("SLAM (planeslam run: ATE rmse after SE(3) alignment)")
    for name in ("slam_tum", "slam_room", "slam_room_no_loops"):
        summary = load(out, f"{name}/summary.json")
        if not summary:
            continue
        ate = summary.get("metrics", {}).get("ate", {})
        print(f"  {name:20} ATE {100 * ate.get('rmse', float('nan')):.2f} cm "
              f"({ate.get('pairs', 0)} pairs), {summary['frames']} frames, "
              f"{summary['frames_per_second']:.1f} frames/s, {summary['keyframes']} keyframes, "
              f"{summary['loop_closures']} loop closures, {summary['map_planes']} map planes")


def evaluation(out):
    print("planeslam eval against the TUM tools' published values")
    for name, expected in EVAL_REFERENCE.items():
        path = out / f"{name}.txt"
        if not path.exists():
            continue
        got = dict(line.split()[:2] for line in path.read_text().splitlines() if line.strip())
        same = all(got.get(k) == v for k, v in expected.items())
        shown = ", ".join(f"{k.split('.')[0]} {got.get(k)}" for k in expected)
        print(f"  {name:14} {shown}: {'equal' if same else 'DIFFERENT'}")


def graph(out):
    g = load(out, "graph_garage.json")
    if g:
        print(f"pose graph parking-garage.g2o: {g['vertices']} poses, {g['edges']} edges, cost "
              f"{g['initial_cost']:.3f} to {g['final_cost']:.7f} in {g['iterations']} "
              f"iterations, converged {g['converged']}")


def main():
    out = pathlib.Path(sys.argv[1])
    detect_speed(out)
    quality(out)
    odometry(out)
    slam(out)
    evaluation(out)
    graph(out)


if __name__ == "__main__":
    main()
