// HSH .rti files: the sniffing used by relight and info, and the reader.
#include "fuzz_util.h"
#include "ptmkit/texture/rti.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto path = ptmkit::fuzz::input_file(data, size, "input.rti");
  (void)ptmkit::texture::looks_like_rti(path);
  ptmkit::fuzz::expect_value_or_error([&] { (void)ptmkit::texture::summarise_rti(path); });
  return 0;
}
