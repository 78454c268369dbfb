// A parallel loop over [0, n) on every hardware thread, for the CPU reference's stages and the
// host-side work of loading a scene (chunk bounds, LOD building). The room every other room of
// render_core may use: it includes nothing of ours.
#pragma once

#include <cstddef>
#include <functional>

namespace catgs {

// Runs fn(i) for i in [0, n) on all hardware threads, dynamically scheduled in chunks of `grain`
// (at least 1). fn must be safe to call concurrently for different i; returns when all are done.
void parallel_for(std::size_t n, std::size_t grain, const std::function<void(std::size_t)>& fn);

}  // namespace catgs
