// Decode-only floor for `ptmkit fit`: streams every band of a capture's images through the
// same StackReader the fit uses, and discards it. Usage: decode_stack LIGHTS.lp [THREADS]
// [BAND_ROWS]. The default, 64 rows, is the fastest band measured for decoding alone (8 was
// 20% slower; 128 and 500 no faster), so the floor is the decoder's, not the fit's banding.
#include <chrono>
#include <cstdio>
#include <cstdlib>

#include "ptmkit/core/error.h"
#include "ptmkit/core/light_set.h"
#include "ptmkit/core/parallel.h"
#include "ptmkit/core/stack_reader.h"

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: decode_stack LIGHTS.lp [THREADS] [BAND_ROWS]\n");
    return 2;
  }
  try {
    const int threads = argc > 2 ? std::atoi(argv[2]) : 0;
    const int band_rows = argc > 3 ? std::atoi(argv[3]) : 64;
    const ptmkit::ThreadLimit limit(threads);
    const auto t0 = std::chrono::steady_clock::now();
    const ptmkit::LightSet lights = ptmkit::read_lp(argv[1]);
    ptmkit::StackReader reader(lights.images());
    ptmkit::StackBand band;
    double checksum = 0.0;
    // The same storage the fit asks for: 8-bit files stay bytes.
    while (reader.read_band(band_rows, &band, ptmkit::BandStorage::kNative8)) {
      checksum += band.sample(band.images / 2, band.rows / 2, band.width / 2, 0);
    }
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::printf("decoded %d images of %dx%dx%d in %.3f s (%.1f Mpixel/s; checksum %.3f)\n",
                reader.count(), reader.width(), reader.height(), reader.channels(), s,
                reader.count() * double(reader.width()) * reader.height() / s / 1e6, checksum);
  } catch (const ptmkit::Error& e) {
    std::fprintf(stderr, "decode_stack: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
