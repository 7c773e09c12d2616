// Internal to core: one row-sequential decoder per image file.
//
// JPEG (libjpeg-turbo), PNG (libpng) and TIFF (libtiff) are decoded here directly; everything
// else (EXR, camera RAW, unusual TIFF layouts, ...) goes through OpenImageIO, which lives in a
// separate module loaded with dlopen() the first time such a file is met (oiio_bridge.h), so a
// process that only meets the common formats never loads OpenImageIO's dependency chain.
#pragma once

#include <cstddef>
#include <filesystem>
#include <memory>
#include <string>

#include "ptmkit/core/image_io.h"

namespace ptmkit::internal {

struct DecodeSettings {
  // Decoder warnings about damaged data (truncated JPEG, corrupt entropy data, bad PNG CRCs)
  // are errors unless this is set; then the decoder's repair is accepted and the warning is
  // printed to stderr once per file.
  bool allow_damaged = false;
};

struct Header {
  int width = 0;
  int height = 0;
  int channels = 0;  // in the file, alpha included
  PixelFormat format = PixelFormat::kU8;
  // What the file's metadata says (sRGB chunk, gAMA, ICC profile, EXIF ColorSpace), if it
  // says anything (has_colour_metadata); colour_space is meaningful only then.
  bool has_colour_metadata = false;
  ColourSpace colour_space = ColourSpace::kSRGB;
  std::string colour_evidence;  // e.g. "PNG sRGB chunk", "EXIF ColorSpace sRGB"
  int orientation = 1;          // EXIF/TIFF orientation 1..8 (1 = as stored)
  double focal_px = 0.0;        // from EXIF (exif_focal_px); 0 = not given
  std::string focal_evidence;   // which EXIF tags gave it
  std::string codec;            // "jpeg", "png", "tiff", or "oiio:<format>"
};

class Decoder {
 public:
  virtual ~Decoder() = default;
  [[nodiscard]] const Header& header() const { return header_; }
  // Decodes the next `rows` stored rows (top to bottom, as stored, before any orientation) in
  // the file's own sample type, every channel, tightly packed. Throws ptmkit::Error naming the
  // file on a decode failure or (unless allowed) on damaged data.
  virtual void read_rows(int rows, void* out) = 0;
  // Passes over the next `rows` stored rows without returning them (a process's share of a
  // fit starts further down). The rows after are exactly what read_rows gives after reading
  // these. Default: read into scratch and drop; JPEG skips what it can without decoding.
  virtual void skip_rows(int rows);
  [[nodiscard]] std::size_t row_bytes() const {
    const std::size_t sample = header_.format == PixelFormat::kU8    ? 1
                               : header_.format == PixelFormat::kU16 ? 2
                                                                     : 4;
    return static_cast<std::size_t>(header_.width) * static_cast<std::size_t>(header_.channels) *
           sample;
  }

 protected:
  Header header_;
};

// Opens `path` with the decoder its first bytes call for. Checks, before anything is
// allocated for pixels: a regular file, the declared size against the named limits of
// image_io.h and (where the format allows a bound) against the file's size. Throws
// ptmkit::Error naming the file.
std::unique_ptr<Decoder> open_decoder(const std::filesystem::path& path,
                                      const DecodeSettings& settings = {});

// The format-specific openers (the file is known to be regular; `file_bytes` its size).
std::unique_ptr<Decoder> open_jpeg(const std::filesystem::path& path, std::uintmax_t file_bytes,
                                   const DecodeSettings& settings);
std::unique_ptr<Decoder> open_png(const std::filesystem::path& path, std::uintmax_t file_bytes,
                                  const DecodeSettings& settings);
// Returns null when the TIFF's layout is one the direct reader does not handle (tiles,
// planar, palette, sub-byte or signed samples, ...): OpenImageIO reads those.
std::unique_ptr<Decoder> open_tiff(const std::filesystem::path& path, std::uintmax_t file_bytes,
                                   const DecodeSettings& settings);
std::unique_ptr<Decoder> open_oiio(const std::filesystem::path& path,
                                   const DecodeSettings& settings);

// Checks declared dimensions against kMaxImageSidePx and kMaxImagePixels; throws naming the
// file.
void check_dimensions(const std::filesystem::path& path, long long width, long long height,
                      long long channels);

// Parses an EXIF block (starting at the TIFF header, "II*\0" or "MM\0*") for the orientation
// (0x0112), and in the EXIF sub-IFD the ColorSpace tag (0xA001) and what gives the focal length
// in pixels: FocalLength (0x920A), FocalPlaneXResolution (0xA20E) with its unit (0xA210),
// PixelXDimension (0xA002), FocalLengthIn35mmFilm (0xA405). Bounded: never reads outside
// [data, data + size). Unknown or malformed: orientation 1, every other field 0.
struct ExifFacts {
  int orientation = 1;
  int colour_space_tag = 0;        // 1 = sRGB, 0xFFFF = uncalibrated, 0 = absent
  double focal_mm = 0.0;           // the lens's focal length
  double focal_plane_x_res = 0.0;  // sensor pixels per focal_plane_unit, across the width
  int focal_plane_unit = 2;        // 2 inch (the default), 3 cm, 4 mm, 5 micrometre
  long pixel_x_dimension = 0;      // the width the camera recorded
  double focal_35mm = 0.0;         // the 35 mm film equivalent, mm
};
ExifFacts parse_exif(const unsigned char* data, std::size_t size);

// The focal length in pixels an image of stored_width x stored_height (before orientation) was
// taken with, from its EXIF facts; 0 when they do not say. From the lens and the sensor's pixel
// pitch where both are there (FocalLength x FocalPlaneXResolution, scaled to the stored width
// where the camera recorded another), else from the 35 mm equivalent over the frame's diagonal
// (43.27 mm): the equivalent is rounded to a millimetre, so good to a few per cent. A pitch
// that implies a sensor under 1 mm or over 100 mm wide is not believed. `evidence` says which.
double exif_focal_px(const ExifFacts& exif, int stored_width, int stored_height,
                     std::string* evidence);

// The public description of a header: displayed size (orientation applied), colour space from
// the metadata or the sample type's default (image_io.h), and why.
ImageInfo info_from_header(const Header& header);

// Checks an OpenEXR file's header (magic number already seen) before OpenEXR reads it:
// every attribute's declared size against the bytes left in the file, the data window against
// check_dimensions, and the chunk offset table the window implies against the file's size.
// Deep images are refused. Throws ptmkit::Error naming the file.
void check_exr_header(const std::filesystem::path& path, std::uintmax_t file_bytes);

// Applies the settings' damaged-data policy to a decoder warning: throws unless allowed.
void damaged_data(const std::filesystem::path& path, const DecodeSettings& settings,
                  const std::string& warning, bool* already_warned);

}  // namespace ptmkit::internal
