// Reading and writing image files.
//
// In: JPEG (libjpeg-turbo), PNG (libpng) and TIFF (libtiff; 8/16-bit integer and 32-bit float
// strips) are decoded directly; everything else - EXR, camera RAW through LibRaw, TIFF
// layouts the direct reader does not take, and any other format OpenImageIO reads - goes
// through OpenImageIO, loaded as a separate module (ptmkit_oiio) only when such a file is met,
// so commands that read the common formats start without its hundreds of libraries. The
// decoder is chosen by the file's first bytes, not its extension.
//
// Out: PNG directly (libpng); TIFF, EXR and JPEG through the OpenImageIO module. Writes are
// atomic: the image goes to a temporary file beside the target and is renamed over it only
// after the encoder and the close (flush) reported success, so a failed write - a full disk
// included - leaves no partial file. Every failure throws ptmkit::Error naming the file.
//
// Inputs are bounded before they are trusted: declared dimensions are checked against the
// limits below (and, for JPEG and PNG, against what the file's size can hold) before any pixel
// memory is allocated, and a decoder's warning about damaged data (a truncated JPEG, corrupt
// entropy-coded data, a bad PNG checksum) is an error unless ImageReadOptions::allow_damaged.
// A JPEG of several scans (progressive) is decoded into a buffer of all its coefficients
// before its first row: that buffer is checked against the memory available first, more than
// 500 scans are an error, and where damage is an error decoding stops at the first warning.
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "ptmkit/core/image.h"

namespace ptmkit {

// Sample type of a file on disk.
enum class PixelFormat { kU8, kU16, kF32 };
[[nodiscard]] std::string_view to_string(PixelFormat format);

// Largest width or height accepted, in pixels (JPEG's own limit is 65500; gigapixel TIFFs of
// paintings stay below this).
inline constexpr long long kMaxImageSidePx = 1LL << 18;  // 262144
// Largest pixel count of one image: 2^32 (4.3 gigapixels; a 1-gigapixel capture fits 4 times).
inline constexpr long long kMaxImagePixels = 1LL << 32;

struct ImageReadOptions {
  // Accept images whose decoder reports damaged data (a truncated JPEG is completed with grey,
  // corrupt blocks are filled) with a warning on stderr, instead of an error. For damaged
  // archives; a fit of such images fits the filler too.
  bool allow_damaged = false;
};

struct ImageInfo {
  int width = 0;
  int height = 0;
  int channels = 0;
  PixelFormat format = PixelFormat::kU8;
  // From the file's metadata where it says (PNG sRGB/gAMA/iCCP chunks, an ICC profile, EXIF
  // ColorSpace); otherwise by sample type: 8-bit files are sRGB (what cameras write in JPEG,
  // and what 8-bit PNGs are by convention), 16-bit and float files are linear (what raw
  // converters write without a profile: `dcraw -4`, LibRaw's 16-bit linear output, and
  // photometric-stereo data sets; renderers' float output).
  ColourSpace colour_space = ColourSpace::kSRGB;
  // Whether colour_space came from the file's metadata, and which.
  bool colour_from_metadata = false;
  std::string colour_evidence;  // e.g. "PNG sRGB chunk", "16-bit, no colour metadata"
  // EXIF/TIFF orientation, 1..8 (1: stored as displayed). read_image() and the stack reader
  // apply it, so width and height here are as displayed (swapped for 5..8).
  int orientation = 1;
  // The focal length in pixels the camera recorded in EXIF (JPEG, PNG, TIFF, and the files
  // OpenImageIO reads, camera RAW among them), for the stored width (the same in pixels
  // whatever the orientation); 0 when the file does not say. From FocalLength and the sensor's
  // pixel pitch (FocalPlaneXResolution) where both are there, else from the 35 mm equivalent
  // over the frame's diagonal. focal_evidence says which.
  double focal_px = 0.0;
  std::string focal_evidence;
};

// Human-readable name of an EXIF orientation code ("rotate 90 CW", ...).
[[nodiscard]] std::string_view orientation_name(int orientation);

// Header only: size (as displayed), channels, sample type, colour space, orientation.
[[nodiscard]] ImageInfo probe_image(const std::filesystem::path& path);

// The whole image as floats (integers normalised to 0..1), all channels, turned upright by
// its EXIF orientation. Refuses (before decoding) an image whose float copy would not fit in
// the memory the system reports available.
[[nodiscard]] Image read_image(const std::filesystem::path& path,
                               const ImageReadOptions& options = {});

struct ImageWriteOptions {
  // Sample type written. Integer formats clamp to [0, 1] and round to nearest.
  // The file type comes from the extension (.png, .tif/.tiff, .exr, .jpg).
  PixelFormat format = PixelFormat::kU8;
  // JPEG quality 1..100, used only for .jpg.
  int jpeg_quality = 95;
  // Channel names (EXR only; empty = R, G, B, A or Y). OpenEXR sorts channels by name, so
  // names that sort in the intended order keep the layout on reading back.
  std::vector<std::string> channel_names = {};
  // JPEG only: the camera to record in an EXIF block, as cameras do: FocalLength, the sensor's
  // pixel pitch (FocalPlaneXResolution, in pixels per cm, for the image's width), the width
  // recorded (PixelXDimension) and the 35 mm equivalent (FocalLengthIn35mmFilm, over the
  // diagonal). Read back as ImageInfo::focal_px. nullopt: no EXIF block.
  struct ExifCamera {
    double focal_mm = 0.0;         // > 0
    double sensor_width_mm = 0.0;  // > 0: the image's full width on the sensor
  };
  std::optional<ExifCamera> exif_camera = std::nullopt;
};

// Writes `image` atomically; the view's colour space is recorded in the file's metadata.
void write_image(const std::filesystem::path& path, ConstImageViewF image,
                 const ImageWriteOptions& options = {});

// Normal maps: unit normals, x, y, z in R, G, B (light frame). Written as floats to .exr;
// to any other type as (n + 1) / 2 in 16 bits (the usual RTI normal-map encoding).
void write_normal_map(const std::filesystem::path& path, ConstImageViewF normals);
// Reads either form: float files as stored, integer files decoded from (n + 1) / 2.
[[nodiscard]] Image read_normal_map(const std::filesystem::path& path);

}  // namespace ptmkit
