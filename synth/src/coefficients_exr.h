// Writing the polynomial world's coefficients (internal to synth).
#pragma once

#include <filesystem>

#include "ptmkit/core/coefficients.h"

namespace ptmkit::synth::detail {

// Writes an kRGB map as an 18-channel float EXR, channel 6 c + k = term a_k of colour c,
// atomically. Throws ptmkit::Error naming the file on failure.
void write_coefficients_exr(const std::filesystem::path& path, const CoefficientMap& map);

}  // namespace ptmkit::synth::detail
