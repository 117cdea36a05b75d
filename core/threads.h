#pragma once
// The size of a TBB task arena for a number of worker threads that a caller asked for.
#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cstddef>

namespace meshsweeper {

// `threads` workers (0: TBB's default), at most TBB's current limit (global_control's
// max_allowed_parallelism: the cores, unless the program set it). More could not run at once
// anyway, and TBB would print a warning on standard error for each arena that asked.
inline int arenaConcurrency(unsigned threads) {
  if (threads == 0) return static_cast<int>(tbb::task_arena::automatic);
  const std::size_t limit =
      tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism);
  return static_cast<int>(std::max<std::size_t>(1, std::min<std::size_t>(threads, limit)));
}

}  // namespace meshsweeper
