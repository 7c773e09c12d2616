// Thread control. ptmkit parallelises with TBB; results never depend on the thread count
// (work is split into fixed pieces and combined in a fixed order).
#pragma once

#include <functional>
#include <memory>

namespace ptmkit {

// Limits TBB to `threads` worker threads while alive; 0 means all cores.
class ThreadLimit {
 public:
  explicit ThreadLimit(int threads);
  ~ThreadLimit();
  ThreadLimit(const ThreadLimit&) = delete;
  ThreadLimit& operator=(const ThreadLimit&) = delete;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Progress callback: fraction done in [0, 1]. Called from the calling thread only.
using ProgressFn = std::function<void(double fraction)>;

}  // namespace ptmkit
