#include "progress.h"

#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <sstream>
#include <vector>

#include "ptmkit/core/error.h"

namespace ptmkit::app {

ProgressFn make_progress(const std::string& label) {
  if (::isatty(2) == 0) return {};
  return [label, last = -1](double fraction) mutable {
    const int pct = static_cast<int>(std::lround(std::clamp(fraction, 0.0, 1.0) * 100.0));
    if (pct == last) return;
    last = pct;
    constexpr int kWidth = 30;
    const int filled = pct * kWidth / 100;
    std::string bar(static_cast<std::size_t>(filled), '=');
    if (filled < kWidth) bar += '>';
    bar.resize(kWidth, ' ');
    std::fprintf(stderr, "\r%s [%s] %3d%%", label.c_str(), bar.c_str(), pct);
    if (pct == 100) std::fprintf(stderr, "\n");
    std::fflush(stderr);
  };
}

}  // namespace ptmkit::app
