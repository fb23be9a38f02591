#pragma once
// The aliasing scene: a ring corridor of identical segments (see MakeRingCorridor).
#include "planeslam/datasets/synthetic_scene.hpp"

namespace planeslam::datasets {

/// Octagonal ring corridor around a central block (inner wall apothem 1.2 m, outer 2.4 m,
/// height 2.6 m): eight identical segments, each with a door recess in its outer wall and a box
/// against its inner wall. Every segment looks like the others, rotated by 45 degrees, so a place
/// recognition that goes by appearance alone is fooled seven times out of eight.
SyntheticScene MakeRingCorridor();

}  // namespace planeslam::datasets
