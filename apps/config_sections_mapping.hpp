#pragma once
/// Config sections of the mapping module: "pose_graph" (mapping::PoseGraphConfig). Further mapping
/// sections are registered in config_sections_mapping.cpp as well.
#include "config.hpp"
#include "planeslam/mapping/pose_graph.hpp"
