// Helpers shared by the synth tests (synth_*_test.cc): a preset at a small size with the
// running test's seed.
#pragma once

#include <string>

#include "ptmkit/synth/synth.h"
#include "test_util.h"

namespace ptmkit::test {

inline synth::SynthOptions small_options(const std::string& preset = "default", int size = 64) {
  synth::SynthOptions o = synth::preset_options(preset);
  o.width = size;
  o.height = size;
  o.seed = ptmkit::test::test_seed();
  return o;
}

}  // namespace ptmkit::test
