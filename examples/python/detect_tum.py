import sys
import planeslam

# The first frame of a TUM RGB-D folder, read with the camera and profile `planeslam run` uses.
seq = planeslam.read_sequence(sys.argv[1])
stamp, depth, gt_pose = seq[0]
result = planeslam.detect(depth, seq.intrinsics, depth_scale=seq.depth_scale, sensor=seq.profile)
print(f"{result.method}: {len(result.planes)} planes at t = {stamp:.6f}")
for p in result.planes:
    print(f"plane {p.id}: n = {p.normal.round(3)}, d = {p.d:.3f} m, {p.points} px")
