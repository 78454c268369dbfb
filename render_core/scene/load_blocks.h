// Parallel loading: a per-Gaussian loop split into blocks of consecutive rows, run on a few
// threads (issue 37: a 1 GiB PLY parsed on one core took 35-47 s). The calling thread is the only
// one that reports progress, so LoadProgress keeps its contract (called on the
// loading thread, rising, every block) and a callback that throws (a server that is stopping)
// cancels the load.
#pragma once

#include <cstdint>
#include <functional>

namespace catgs {

// Threads a load uses: `requested` when positive, else the hardware's thread count (at least 1).
int load_threads(int requested);

// Runs block(b) for every b in [0, blocks) on load_threads(threads) threads, handing the blocks
// out in increasing order. The calling thread calls tick(k) for k = 1, 2, ... as the k-th block
// finishes (by any thread), so progress keeps one report per block, on the loading thread; with
// one thread it runs the blocks itself. Errors: the exception of the lowest failing block is
// rethrown on the calling thread once every thread has stopped; blocks above it are skipped,
// those below it all run, so with blocks that fail at their first bad row the error is the one a
// serial walk would meet first. An exception from tick stops the remaining blocks and is
// rethrown.
void run_blocks(uint64_t blocks, int threads, const std::function<void(uint64_t)>& block,
                const std::function<void(uint64_t)>& tick = {});

}  // namespace catgs
