// Internal to core: EXIF orientation as photo viewers apply it.
#pragma once

#include <cstddef>
#include <cstring>

namespace ptmkit::internal {

// Displayed size for a stored width x height.
inline bool swaps_axes(int orientation) { return orientation >= 5 && orientation <= 8; }

// The stored pixel (x, y) shown at displayed (dx, dy), for a stored image of w x h. Orientation
// says where the stored first row and column are shown: 2 mirrored left-right, 3 turned 180,
// 4 mirrored top-bottom, 5 transposed, 6 turned 90 clockwise for display, 7 transversed, 8
// turned 90 counter-clockwise.
inline void stored_pixel(int orientation, int w, int h, int dx, int dy, int* x, int* y) {
  switch (orientation) {
    case 2:
      *x = w - 1 - dx;
      *y = dy;
      return;
    case 3:
      *x = w - 1 - dx;
      *y = h - 1 - dy;
      return;
    case 4:
      *x = dx;
      *y = h - 1 - dy;
      return;
    case 5:
      *x = dy;
      *y = dx;
      return;
    case 6:
      *x = dy;
      *y = h - 1 - dx;
      return;
    case 7:
      *x = w - 1 - dy;
      *y = h - 1 - dx;
      return;
    case 8:
      *x = w - 1 - dy;
      *y = dx;
      return;
    default:
      *x = dx;
      *y = dy;
      return;
  }
}

// Copies displayed row `dy`, columns [dx0, dx0 + n), of a stored image (w x h pixels of
// `pixel_bytes` bytes, tightly packed) into `out`.
inline void displayed_row(const unsigned char* stored, int orientation, int w, int h,
                          std::size_t pixel_bytes, int dy, int dx0, int n, unsigned char* out) {
  for (int i = 0; i < n; ++i) {
    int x = 0, y = 0;
    stored_pixel(orientation, w, h, dx0 + i, dy, &x, &y);
    std::memcpy(out + static_cast<std::size_t>(i) * pixel_bytes,
                stored + (static_cast<std::size_t>(y) * static_cast<std::size_t>(w) +
                          static_cast<std::size_t>(x)) *
                             pixel_bytes,
                pixel_bytes);
  }
}

}  // namespace ptmkit::internal
