// FitReport as a JSON object (shared by FitReport::to_json and FitRunReport::to_json).
#pragma once

#include <nlohmann/json.hpp>

#include "ptmkit/fit/fit.h"

namespace ptmkit::fit::internal {

[[nodiscard]] nlohmann::json fit_report_json(const FitReport& report);

}  // namespace ptmkit::fit::internal
