// A progress bar on stderr when it is a terminal; silent otherwise (scripts, CI, pipes).
#pragma once

#include <string>

#include "ptmkit/core/parallel.h"

namespace ptmkit::app {

// Returns a callback drawing "label [=====>    ] 45%" on a terminal, or an empty function.
ProgressFn make_progress(const std::string& label);

}  // namespace ptmkit::app
