// Every JSON file the project reads: boards, sample planes, cameras, dome descriptions and
// light JSON (the same reader: read_dome_json). The first byte picks the reader.
#include "fuzz_util.h"
#include "ptmkit/calib/camera.h"
#include "ptmkit/calib/dome.h"
#include "ptmkit/core/board.h"
#include "ptmkit/core/plane.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  const auto path = ptmkit::fuzz::input_file(data + 1, size - 1, "input.json");
  ptmkit::fuzz::expect_value_or_error([&] {
    switch (data[0] % 4) {
      case 0:
        (void)ptmkit::read_board_json(path);
        break;
      case 1:
        (void)ptmkit::read_plane_json(path);
        break;
      case 2:
        (void)ptmkit::calib::read_camera_json(path);
        break;
      default:
        (void)ptmkit::calib::read_dome_json(path, ptmkit::calib::DomeOptions{});
        break;
    }
  });
  return 0;
}
