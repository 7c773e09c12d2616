// Streaming reader for a capture stack: N photographs of the same size, read together in
// bands of rows so that no caller ever needs the whole decoded stack in memory.
//
// All N files stay open (one decoder each, image_io.h); a band is decoded from the N files in
// parallel. Options (StackReadOptions) select a rectangle of the photos (a crop and/or a mask's
// bounding box), override the colour space, and accept damaged files; orientation (EXIF) is
// applied as photo viewers do, and must be the same for every image of the stack. Band layout:
// image-major, then row, then pixel, then channel, so that each image's part of the band is one
// contiguous block, and the band is an N x (rows*width*channels) row-major matrix — which is what a
// shared-pseudo-inverse fit multiplies.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "ptmkit/core/collective.h"
#include "ptmkit/core/image_io.h"

namespace ptmkit {

// A rectangle of pixels: x to the right, y down, origin at the top-left pixel of the photo as
// displayed (after its EXIF orientation).
struct PixelRect {
  int x = 0;
  int y = 0;
  int width = 0;
  int height = 0;
  [[nodiscard]] bool operator==(const PixelRect&) const = default;
};
// "x,y,w,h" (integers) or ptmkit::Error.
[[nodiscard]] PixelRect parse_pixel_rect(const std::string& text);

// What the images' samples are taken to be.
enum class InputColourSpace {
  kAuto,    // the files' metadata, else by sample type (ImageInfo::colour_space)
  kSRGB,    // sRGB-encoded, whatever the files say
  kLinear,  // proportional to light, whatever the files say
};
// "auto", "srgb" or "linear"; ptmkit::Error otherwise.
[[nodiscard]] InputColourSpace parse_input_colour_space(const std::string& text);

struct StackReadOptions {
  ImageReadOptions image;  // allow_damaged
  InputColourSpace colour_space = InputColourSpace::kAuto;
  // Only this rectangle of every photo is read (photo pixels as displayed). It must lie inside
  // the photos. Unset: the whole photo.
  std::optional<PixelRect> crop;
  // A mask image of the photos' displayed size: texels whose first channel is above half of
  // full scale are the object. Only the mask's bounding box (within the crop, if any) is read,
  // and the samples of texels outside the mask are 0 in every image (a fit writes them black).
  std::filesystem::path mask;
  // Only rows [begin, end) of that region (after the crop and the mask's box) are read: one
  // process's share of a fit divided among several (core/collective.h). Rows above are
  // still decoded and dropped where the format cannot seek (JPEG, PNG, strip TIFF). The mask's
  // box is found on the whole region first, so every share has the region's width.
  std::optional<RowRange> rows;
};

// What the reader took the stack to be (fit reports carry it).
struct StackInputSummary {
  int full_width = 0;  // photo size as displayed
  int full_height = 0;
  PixelRect region;  // what is read, in photo pixels
  int orientation = 1;
  ColourSpace colour_space = ColourSpace::kSRGB;
  std::string colour_space_source;  // "--input-colour-space", or the files' evidence
  std::string mask;                 // the mask file, if any
  std::uint64_t masked_out_texels = 0;
  std::string codec;  // of the first file: jpeg, png, tiff, oiio:<format>
  [[nodiscard]] std::string to_json() const;
};

// How a band holds its samples.
enum class BandStorage {
  kFloat,    // always floats, integer files scaled to 0..1 (v / 255, v / 65535)
  kNative8,  // 8-bit files keep their bytes (a quarter of the memory traffic); others as kFloat
};

struct StackBand {
  int y0 = 0;    // first image row in this band (0 = top)
  int rows = 0;  // rows in this band
  int width = 0;
  int channels = 0;
  int images = 0;
  // Which of the two buffers holds this band: bytes (8-bit files read with kNative8, value
  // v meaning v / 255) or samples (everything else). The other one is empty.
  bool is_u8 = false;
  std::vector<float> samples;       // images * rows * width * channels floats
  std::vector<std::uint8_t> bytes;  // the same layout, one byte per sample

  [[nodiscard]] std::size_t image_stride() const {
    return static_cast<std::size_t>(rows) * width * channels;
  }
  [[nodiscard]] const float* image(int i) const { return samples.data() + i * image_stride(); }
  [[nodiscard]] float* image(int i) { return samples.data() + i * image_stride(); }
  [[nodiscard]] const std::uint8_t* image_u8(int i) const {
    return bytes.data() + i * image_stride();
  }
  // Either storage, as a 0..1 float.
  [[nodiscard]] float sample(int i, int row, int x, int c) const {
    const std::size_t k = (static_cast<std::size_t>(row) * width + x) * channels + c;
    return is_u8 ? static_cast<float>(image_u8(i)[k]) / 255.0f : image(i)[k];
  }
};

class StackReader {
 public:
  // Opens every file and checks that all share width, height, channel count and orientation.
  // Throws ptmkit::Error naming the first file that is missing, unreadable, damaged, of another
  // size or orientation, and for a crop outside the photos or a mask of another size.
  // Orientations other than 1 (as stored) are applied by decoding each image whole on the first
  // band, so such a stack holds every image in memory in its own sample type.
  explicit StackReader(std::vector<std::filesystem::path> files,
                       const StackReadOptions& options = {});
  ~StackReader();
  StackReader(const StackReader&) = delete;
  StackReader& operator=(const StackReader&) = delete;

  // Size of what is read: the region (crop / mask box), or the whole photo.
  [[nodiscard]] int width() const;
  [[nodiscard]] int height() const;
  [[nodiscard]] int channels() const;
  [[nodiscard]] int count() const;
  // Of the first file (all agree on size), with colour_space as decided by the options.
  [[nodiscard]] const ImageInfo& info() const;
  [[nodiscard]] const StackInputSummary& summary() const;
  // Texel (0, 0) of a band is photo pixel (origin_x, origin_y).
  [[nodiscard]] int origin_x() const { return summary().region.x; }
  [[nodiscard]] int origin_y() const { return summary().region.y; }
  [[nodiscard]] const std::vector<std::filesystem::path>& files() const;

  // Decodes the next `rows` rows (fewer at the bottom) of every image into `band`, reusing its
  // storage. Returns false once every row has been read. Throws ptmkit::Error naming the file
  // on a decode failure. Rows come top to bottom; the reader cannot seek backwards.
  // With kNative8, 8-bit files fill band->bytes instead (band->is_u8).
  bool read_band(int rows, StackBand* band, BandStorage storage = BandStorage::kFloat);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// The sample channels of a stack whose files or images have `channels` channels: an alpha
// channel is not a sample (RGBA gives 3, grey + alpha 1), and at most 3 are read. One rule for
// files (StackReader) and images in memory (read_image_band).
[[nodiscard]] int sample_channels(int channels);

// Rows [y0, y0 + rows) (fewer at the bottom) of images already in memory into `band`, as
// StackReader would give them from files (float storage, sample_channels' rule, image-major).
// Returns false when y0 is past the last row. Throws ptmkit::Error when the images are empty,
// differ in size or channel count, or a sample read is NaN or infinite (naming the image's
// index).
bool read_image_band(const std::vector<Image>& images, int y0, int rows, StackBand* band);

// Convenience for small stacks (tests, comparisons): every image decoded whole.
[[nodiscard]] std::vector<Image> read_stack(const std::vector<std::filesystem::path>& files,
                                            const StackReadOptions& options = {});

}  // namespace ptmkit
