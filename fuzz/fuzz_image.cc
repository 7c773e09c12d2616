// Image headers and pixels through the stack reader (what fit reads), for each file type the
// project writes; the first byte picks the extension (readers are chosen by it first).
#include "fuzz_util.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/core/limits.h"
#include "ptmkit/core/stack_reader.h"

// Decoding is the cost here, and it grows with the pixels an input declares. Under the
// sanitizers a decode near the other targets' 1 GiB budget takes seconds (ten and more on a
// loaded machine), which would read as a timeout; a 256 MiB budget keeps every unit short.
// The readers' refusals past the budget are exercised the same way.
//
// EXR goes through OpenImageIO, a module loaded on the first such file. Under the sanitizers,
// with the full unwind on malloc scripts/fuzz.sh sets for this target, that load alone takes ten
// seconds and more; it is paid here, before any unit is timed, so the first EXR input does not read
// as a timeout.
extern "C" int LLVMFuzzerInitialize(int*, char***) {
  ptmkit::set_memory_budget_bytes(std::uint64_t{256} << 20);
  static const std::uint8_t kNotAnImage[] = {'n', 'o', 't'};
  const auto path = ptmkit::fuzz::input_file(kNotAnImage, sizeof kNotAnImage, "load.exr");
  ptmkit::fuzz::expect_value_or_error([&] { (void)ptmkit::probe_image(path); });
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  static const char* const kNames[] = {"input.png", "input.jpg", "input.tif", "input.exr"};
  const auto path = ptmkit::fuzz::input_file(data + 1, size - 1, kNames[data[0] % 4]);
  ptmkit::fuzz::expect_value_or_error([&] { (void)ptmkit::probe_image(path); });
  ptmkit::fuzz::expect_value_or_error([&] { (void)ptmkit::read_stack({path}); });
  return 0;
}
