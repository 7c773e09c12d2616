// .ptm files through the generic reader entry points (every format the reader accepts),
// then decoding to coefficients as relight does.
#include "fuzz_util.h"
#include "ptmkit/texture/ptm.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto path = ptmkit::fuzz::input_file(data, size, "input.ptm");
  ptmkit::fuzz::expect_value_or_error([&] { (void)ptmkit::texture::read_ptm_info(path); });
  ptmkit::fuzz::expect_value_or_error([&] {
    const ptmkit::CoefficientMap map = ptmkit::texture::read_ptm(path);
    (void)map.width;
  });
  return 0;
}
