"""Trajectory metrics with the semantics and defaults of `planeslam eval` (evo's by default, the
TUM RGB-D tools' with tum=True), on trajectory files or (N, 8) arrays t tx ty tz qx qy qz qw.
Each returns the dict `planeslam eval ... --json` writes, plus the errors per pair."""
from ._planeslam._eval import ape, rpe

__all__ = ["ape", "rpe"]
