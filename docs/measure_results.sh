#!/usr/bin/env bash
# Re-measures every figure of docs/RESULTS.md and prints the headline ones.
#
#   docs/measure_results.sh [PLANESLAM [DATA_DIR [OUT_DIR]]]
#
#   PLANESLAM  the planeslam executable, built Release with PCL (the bench baselines);
#              default: build/bin/planeslam
#   DATA_DIR   the shared real data; default: $PLANESLAM_DATA_DIR, else ../shared/data
#   OUT_DIR    where the raw outputs go (replaced); default: results_out
#
# Relative paths are taken from the repository root. `make results` builds and runs this.
# 3 to 6 minutes on a 2-core machine. Speed is reported as ratios of methods timed in one
# process on the same frames, which holds on a busy machine; absolute milliseconds do not.
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$ROOT"
PLANESLAM=${1:-build/bin/planeslam}
DATA=${2:-${PLANESLAM_DATA_DIR:-../shared/data}}
OUT=${3:-results_out}

[[ -x $PLANESLAM ]] || { echo "measure_results: no executable $PLANESLAM (build first)" >&2; exit 2; }
[[ -d $DATA ]] || { echo "measure_results: no data folder $DATA" >&2; exit 2; }
PLANESLAM=$(cd "$(dirname "$PLANESLAM")" && pwd)/$(basename "$PLANESLAM")
DATA=$(cd "$DATA" && pwd)
export PLANESLAM_DATA_DIR=$DATA
rm -rf "$OUT"
mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)

TUM=$DATA/tum_fr3_structure_notexture_far
TRAJ=$DATA/trajectories
KINECT=(-c config/tum_fr3.yaml -c config/detection_kinect.yaml)
START=$SECONDS

# step NAME COMMAND...: runs COMMAND with stdout to OUT/NAME.txt, stderr to OUT/NAME.log.
step() {
  local name=$1 t0=$SECONDS
  shift
  printf '%-22s' "$name" >&2
  "$@" >"$OUT/$name.txt" 2>"$OUT/$name.log" || {
    echo " failed; see $OUT/$name.log" >&2
    exit 1
  }
  echo " $((SECONDS - t0)) s" >&2
}

{
  echo "planeslam: $PLANESLAM"
  echo "data: $DATA"
  echo "source: $(git -C "$ROOT" describe --always --dirty 2>/dev/null || echo unknown)"
  echo "cpus: $(nproc), $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | xargs)"
  echo "started: $(date -u +%FT%TZ), load average $(cut -d' ' -f1-3 /proc/loadavg)"
} >"$OUT/machine.txt"

# 1. Detection speed: the 14 default frames (every 50th TUM frame, the Kinect PCDs, the laser
# scans), every method interleaved with PCL's OrganizedMultiPlaneSegmentation on each frame; three
# runs, as the machine's load changes from minute to minute. Then grid with other grid sizes.
for run in 1 2 3; do
  step detect_speed_$run "$PLANESLAM" bench detect --repeat 5 -q \
    --methods grid,grid-fast,grid-paper,point,point-paper,pcl_omps --json "$OUT/detect_speed_$run.json"
done
for k in 4 5 6; do
  step detect_speed_grid$k "$PLANESLAM" bench detect --repeat 5 -q --methods grid,pcl_omps \
    --set grid.cell_size=$k --json "$OUT/detect_speed_grid$k.json"
done

# 2. Detection quality: synthetic scenes against their ground-truth labels, and TUM repeatability.
step quality_synthetic "$PLANESLAM" bench detect --quality -q -c config/detection_synthetic.yaml \
  --methods grid,grid-fast,grid-paper,point,pcl_omps --json "$OUT/quality_synthetic.json"
step quality_tum "$PLANESLAM" bench detect --quality -q "${KINECT[@]}" \
  --methods grid,grid-fast,grid-paper,point,pcl_omps --json "$OUT/quality_tum.json"

# 3. Frame-to-frame odometry against PCL GICP.
step odometry_tum "$PLANESLAM" bench odometry "$TUM" -q "${KINECT[@]}" --out "$OUT/odometry_tum" \
  --json "$OUT/odometry_tum.json"
step odometry_ate_planes "$PLANESLAM" eval ape "$TUM/groundtruth.txt" "$OUT/odometry_tum/planes.txt" -a
step odometry_ate_gicp "$PLANESLAM" eval ape "$TUM/groundtruth.txt" "$OUT/odometry_tum/gicp.txt" -a

# 4. SLAM: TUM fr3 and the built-in synthetic room (rendering included in its time).
step slam_tum "$PLANESLAM" run "$TUM" -q "${KINECT[@]}" --set octomap.enabled=false \
  --out "$OUT/slam_tum"
step slam_room "$PLANESLAM" run -q --set octomap.enabled=false --out "$OUT/slam_room"
step slam_room_no_loops "$PLANESLAM" run -q --set octomap.enabled=false \
  --set slam.loop_closure=false --out "$OUT/slam_room_no_loops"

# 5. Trajectory evaluation against the TUM tools' published values (data README).
step eval_fr1_ate "$PLANESLAM" eval ape "$TRAJ/freiburg1_xyz-groundtruth.txt" \
  "$TRAJ/freiburg1_xyz-rgbdslam.txt" --tum
step eval_fr2_ate "$PLANESLAM" eval ape "$TRAJ/fr2_desk_groundtruth.txt" "$TRAJ/fr2_desk_ORB.txt" --tum
step eval_fr1_rpe "$PLANESLAM" eval rpe "$TRAJ/freiburg1_xyz-groundtruth.txt" \
  "$TRAJ/freiburg1_xyz-rgbdslam.txt" --tum --fixed-delta --delta 1 --delta-unit s

# 6. Pose graph: parking-garage.g2o with the information used as Ceres' pose_graph_3d uses it.
step graph_garage "$PLANESLAM" graph optimize "$DATA/pose_graphs/parking-garage.g2o" -q \
  --raw-information --set pose_graph.loop_closure_loss=none --out "$OUT/garage_opt.g2o" \
  --json "$OUT/graph_garage.json"

# 7. Throughput: `planeslam run` end to end (start-up to the last file) on one and two threads,
# alternating; the wall time is the last line of each .txt.
timed() {
  local t0=$EPOCHREALTIME
  "$@"
  awk -v a="$t0" -v b="$EPOCHREALTIME" 'BEGIN { printf "wall %.3f s\n", b - a }'
}
for r in 1 2 3; do
  for t in 1 2; do
    step "run_tum_t${t}_$r" timed "$PLANESLAM" run "$TUM" -q --threads "$t" --out "$OUT/run_tum_t$t"
  done
done

echo "finished: $(date -u +%FT%TZ), $((SECONDS - START)) s, load average $(cut -d' ' -f1-3 /proc/loadavg)" \
  >>"$OUT/machine.txt"
python3 docs/headline.py "$OUT" | tee "$OUT/headline.txt"
echo "raw outputs in $OUT/ ($((SECONDS - START)) s)"
