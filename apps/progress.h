// A progress bar on stderr when it is a terminal; silent otherwise (scripts, CI, pipes).
#pragma once

#include <string>

#include "ptmkit/core/parallel.h"

namespace ptmkit::app {

// Returns a callback drawing "label [=====>    ] 45%" on a terminal, or an empty function.
ProgressFn make_progress(const std::string& label);

// Parses "x,y,z" into three doubles; throws ptmkit::Error naming `flag` otherwise.
void parse_vector3(const std::string& text, const std::string& flag, double out[3]);

}  // namespace ptmkit::app
