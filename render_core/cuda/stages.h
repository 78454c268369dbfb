// The stages of the CUDA core in the order a frame runs them, each declared beside its .cu and
// mirroring the CPU reference stage of the same name (cpu/cpu_renderer.h). The CudaRenderer
// (cuda_renderer.cpp, render_catgs.cpp) includes them all from here.
#pragma once

#include "records.h"
#include "preprocess.h"              // stage 1 (exact, vanilla)
#include "speculative_preprocess.h"  // stage 1 (catgs key frames) and the motion M
#include "subframe_features.h"       // catgs sub-frames: frustum cache, features, containment
#include "key_emission.h"            // stage 2: scan, emission
#include "depth_order.h"             // stage 2a': the depth-first sort's order
#include "sort.h"                    // stage 3
#include "tile_ranges.h"             // stage 4 and the heavy-first tile order (vanilla)
#include "rasterize.h"               // stage 5 (vanilla: whole tiles)
#include "task_split.h"              // exact, catgs: split tasks and their order
#include "rasterize_slices.h"        // stage 5 with slices (exact, catgs), and the merge
#include "occlusion_map.h"           // stage 5b: exact frames' occlusion map
#include "colour/yuv420_convert.h"   // after stage 5: RGBA8 -> I420
