// Light files (.lp): read_lp, then what fit and relight do with the set.
#include "fuzz_util.h"
#include "ptmkit/core/light_set.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto path = ptmkit::fuzz::input_file(data, size, "lights.lp");
  ptmkit::fuzz::expect_value_or_error([&] {
    const ptmkit::LightSet set = ptmkit::read_lp(path);
    (void)set.directions();
  });
  return 0;
}
