"""planeslam: plane detection (GBRG/PBRG), plane SLAM and trajectory evaluation.

detect(depth, intrinsics, ...)   planes of one depth image or organized cloud (numpy arrays)
Slam(intrinsics, ...)            `planeslam run` fed frame by frame: track(), finish(), write()
read_sequence(path)              (stamp, depth, gt_pose_or_None) of a sequence folder's frames
eval.ape(ref, est), eval.rpe()   trajectory metrics as `planeslam eval` (evo or TUM semantics)

Bad arrays and options raise ValueError, unreadable files OSError, with the CLI's messages.
"""
from ._planeslam import Detection, Plane, Sequence, Slam, detect, read_sequence
from ._planeslam import _bench_detect_cpp
from . import eval

__all__ = ["Detection", "Plane", "Sequence", "Slam", "detect", "eval", "read_sequence"]
