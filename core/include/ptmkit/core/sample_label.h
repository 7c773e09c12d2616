// Per-sample labels: what a texel's sample under one light is. One definition for the labels
// a robust fit assigns (fit/robust.h) and the truth a synthetic capture renders
// (synth/synth.h, truth/labels/*.png): the codes are the 8-bit values stored in label files.
#pragma once

#include <cstdint>

namespace ptmkit {

enum class SampleLabel : std::uint8_t {
  kInlier = 0,
  // Shadowed: the light does not reach the surface (attached or cast shadow), or (fit) the
  // sample lies far below what the surface's other samples predict.
  kShadow = 1,
  // Specular highlight or saturation: far above the diffuse prediction.
  kHighlight = 2,
};

// The code stored in a label image.
[[nodiscard]] constexpr std::uint8_t label_code(SampleLabel label) {
  return static_cast<std::uint8_t>(label);
}

}  // namespace ptmkit
