// Internal to core: the plain C interface of the ptmkit_oiio module (core/oiio_module/), which
// holds every use of OpenImageIO. core dlopen()s the module the first time a file needs it
// (oiio_client.cc), so a process that reads only JPEG, PNG and TIFF and writes PNG never loads
// OpenImageIO and its dependency chain. Plain C types only: the module and core agree on
// nothing else.
#pragma once

#include <cstddef>

extern "C" {

// Bumped whenever a signature or a struct below changes; core refuses a module of another.
#define PTMKIT_OIIO_ABI 3

enum { kOiioU8 = 0, kOiioU16 = 1, kOiioF32 = 2 };
enum { kOiioColourUnknown = 0, kOiioColourLinear = 1, kOiioColourSRGB = 2 };

struct PtmkitOiioHeader {
  int width;
  int height;
  int channels;
  int format;       // kOiioU8/U16/F32: the type rows are delivered in
  int colour;       // kOiioColour*: what the file's metadata says
  int orientation;  // 1..8
  char format_name[32];
  // The camera's EXIF (0 where absent): FocalLength (mm), FocalPlaneXResolution and its unit
  // (2 inch, 3 cm, 4 mm, 5 micrometre), PixelXDimension, FocalLengthIn35mmFilm (mm).
  double focal_mm;
  double focal_plane_x_res;
  int focal_plane_unit;
  long pixel_x_dimension;
  double focal_35mm;
};

struct PtmkitOiioApi {
  int abi;
  // Opens a file for reading; null on failure with a message in err.
  void* (*open)(const char* path, struct PtmkitOiioHeader* header, char* err, size_t err_len);
  // Reads stored rows [y0, y1) of every channel in header->format. 1: read; 0: failed; 2: read,
  // but the reader reported errors on the way (damaged data it filled in); err says which.
  int (*read_rows)(void* handle, int y0, int y1, void* out, char* err, size_t err_len);
  void (*close)(void* handle);
  // Writes an image: the type chosen by `type_path`'s extension, the bytes to `path`.
  // `pixels` hold height rows of width * channels samples of `format`, rows `stride_bytes`
  // apart. colour: kOiioColour*. channel_names: null or `channels` strings. 0 on failure
  // (the encoder's or the close's error in err).
  int (*write)(const char* type_path, const char* path, int width, int height, int channels,
               int format, const void* pixels, ptrdiff_t stride_bytes, int colour, int jpeg_quality,
               const char* const* channel_names, char* err, size_t err_len);
};

// The module's one exported symbol.
const struct PtmkitOiioApi* ptmkit_oiio_api(void);
}
