// A relight/OpenLIME web folder's info.json (the first byte picks: the description alone, or
// the whole folder, whose planes are then missing or named oddly).
#include "fuzz_util.h"
#include "ptmkit/texture/web_folder.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  const auto path = ptmkit::fuzz::input_file(data + 1, size - 1, "info.json");
  ptmkit::fuzz::expect_value_or_error([&] {
    if (data[0] % 2 == 0) {
      (void)ptmkit::texture::read_web_info(path);
    } else {
      (void)ptmkit::texture::read_web_folder(path.parent_path());
    }
  });
  return 0;
}
