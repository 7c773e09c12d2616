#include "ptmkit/core/stack_reader.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>

#include <tbb/parallel_for.h>
#include <nlohmann/json.hpp>

#include "decoder.h"
#include "orientation.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/limits.h"

namespace fs = std::filesystem;

namespace ptmkit {

PixelRect parse_pixel_rect(const std::string& text) {
  PixelRect r;
  long long v[4] = {};
  std::size_t pos = 0;
  for (int i = 0; i < 4; ++i) {
    const std::size_t end = i < 3 ? text.find(',', pos) : text.size();
    if (end == std::string::npos) {
      throw Error("'" + excerpt(text) + "': expected x,y,width,height (four integers)");
    }
    const std::string part = text.substr(pos, end - pos);
    char* stop = nullptr;
    v[i] = std::strtoll(part.c_str(), &stop, 10);
    if (part.empty() || stop == nullptr || *stop != '\0' || v[i] < 0 || v[i] > kMaxImageSidePx) {
      throw Error("'" + excerpt(text) + "': expected x,y,width,height (four integers >= 0)");
    }
    pos = end + 1;
  }
  if (v[2] < 1 || v[3] < 1) {
    throw Error("'" + excerpt(text) + "': width and height must be at least 1");
  }
  r.x = static_cast<int>(v[0]);
  r.y = static_cast<int>(v[1]);
  r.width = static_cast<int>(v[2]);
  r.height = static_cast<int>(v[3]);
  return r;
}

InputColourSpace parse_input_colour_space(const std::string& text) {
  if (text == "auto") return InputColourSpace::kAuto;
  if (text == "srgb" || text == "sRGB") return InputColourSpace::kSRGB;
  if (text == "linear") return InputColourSpace::kLinear;
  throw Error("input colour space must be auto, srgb or linear, not '" + excerpt(text) + "'");
}

std::string StackInputSummary::to_json() const {
  nlohmann::json j;
  j["photo_size"] = {full_width, full_height};
  j["region"] = {
      {"x", region.x}, {"y", region.y}, {"width", region.width}, {"height", region.height}};
  j["orientation"] = orientation;
  j["orientation_name"] = std::string(orientation_name(orientation));
  j["colour_space"] = std::string(to_string(colour_space));
  j["colour_space_source"] = colour_space_source;
  j["codec"] = codec;
  if (!mask.empty()) {
    j["mask"] = mask;
    j["masked_out_texels"] = masked_out_texels;
  }
  return j.dump();
}

namespace {

std::size_t sample_bytes(PixelFormat f) {
  return f == PixelFormat::kU8 ? 1 : f == PixelFormat::kU16 ? 2 : 4;
}

// 8-bit to float: a table (the same values as v / 255).
const std::array<float, 256>& u8_to_float() {
  static const std::array<float, 256> table = [] {
    std::array<float, 256> t{};
    for (int v = 0; v < 256; ++v) t[static_cast<std::size_t>(v)] = static_cast<float>(v) / 255.0f;
    return t;
  }();
  return table;
}

// One image of the stack: its decoder, and for orientations other than 1 the whole stored image.
struct Source {
  std::unique_ptr<internal::Decoder> decoder;
  std::vector<unsigned char> stored;  // whole image (orientation != 1), else one band of rows
  int next_stored_row = 0;            // orientation 1: next row the decoder gives
  std::vector<unsigned char> rows;    // orientation 1: scratch for a band of stored rows
  std::vector<unsigned char> row;     // orientation != 1: one displayed row
};

std::string size_text(int w, int h) { return std::to_string(w) + "x" + std::to_string(h); }

}  // namespace

struct StackReader::Impl {
  std::vector<fs::path> files;
  std::vector<Source> sources;
  ImageInfo info;
  StackInputSummary summary;
  int channels = 0;  // colour channels read
  bool all_u8 = true;
  int next_row = 0;                // in the region
  std::vector<std::uint8_t> mask;  // region-sized, 1 = object; empty = no mask

  // Fills `dst` (rows x region width x channels, band layout) from image i. Samples are
  // written as bytes (u8 != nullptr) or floats.
  void read_image_rows(std::size_t i, int y0, int n_rows, std::uint8_t* u8, float* f32);
};

void StackReader::Impl::read_image_rows(std::size_t i, int y0, int n_rows, std::uint8_t* u8,
                                        float* f32) {
  Source& s = sources[i];
  const internal::Header& h = s.decoder->header();
  const std::size_t sb = sample_bytes(h.format);
  const std::size_t pixel_bytes = sb * static_cast<std::size_t>(h.channels);
  const PixelRect& r = summary.region;
  const std::size_t out_row =
      static_cast<std::size_t>(r.width) * static_cast<std::size_t>(channels);
  // Source rows (in the file's sample type, file channels) of the region's columns, one at a
  // time, converted into the band.
  const bool same_layout = h.channels == channels;
  const auto emit = [&](const unsigned char* src, int row_in_band) {
    const std::size_t base = static_cast<std::size_t>(row_in_band) * out_row;
    if (same_layout && h.format == PixelFormat::kU8) {
      if (u8 != nullptr) {
        std::memcpy(u8 + base, src, out_row);
      } else {
        const auto& table = u8_to_float();
        for (std::size_t k = 0; k < out_row; ++k) f32[base + k] = table[src[k]];
      }
      return;
    }
    for (int x = 0; x < r.width; ++x) {
      const unsigned char* px = src + static_cast<std::size_t>(x) * pixel_bytes;
      for (int c = 0; c < channels; ++c) {
        const std::size_t k = base + static_cast<std::size_t>(x) * channels + c;
        if (h.format == PixelFormat::kU8) {
          if (u8 != nullptr) {
            u8[k] = px[c];
          } else {
            f32[k] = u8_to_float()[px[c]];
          }
        } else if (h.format == PixelFormat::kU16) {
          std::uint16_t v = 0;
          std::memcpy(&v, px + 2 * static_cast<std::size_t>(c), 2);
          f32[k] = static_cast<float>(v) / 65535.0f;
        } else {
          std::memcpy(&f32[k], px + 4 * static_cast<std::size_t>(c), 4);
        }
      }
    }
  };
  if (h.orientation == 1) {
    const int first = r.y + y0;
    // Rows above the region (or another process's share) are passed over: JPEG entropy-decodes
    // them only, other formats decode and drop them (PNG and strip TIFF cannot seek to a row).
    const std::size_t row_bytes = s.decoder->row_bytes();
    if (s.next_stored_row < first) {
      s.decoder->skip_rows(first - s.next_stored_row);
      s.next_stored_row = first;
    }
    // The common case, 8-bit rows read whole into an 8-bit band: straight into the band.
    if (u8 != nullptr && same_layout && r.x == 0 && r.width == h.width) {
      s.decoder->read_rows(n_rows, u8);
      s.next_stored_row += n_rows;
      return;
    }
    s.rows.resize(row_bytes * static_cast<std::size_t>(n_rows));
    s.decoder->read_rows(n_rows, s.rows.data());
    s.next_stored_row += n_rows;
    for (int k = 0; k < n_rows; ++k) {
      emit(s.rows.data() + row_bytes * static_cast<std::size_t>(k) +
               static_cast<std::size_t>(r.x) * pixel_bytes,
           k);
    }
    return;
  }
  if (s.stored.empty()) {
    check_allocation(files[i], static_cast<std::uint64_t>(s.decoder->row_bytes()) * h.height,
                     "the whole stored image (its orientation is applied after decoding)");
    s.stored.resize(s.decoder->row_bytes() * static_cast<std::size_t>(h.height));
    s.decoder->read_rows(h.height, s.stored.data());
  }
  s.row.resize(pixel_bytes * static_cast<std::size_t>(r.width));
  for (int k = 0; k < n_rows; ++k) {
    internal::displayed_row(s.stored.data(), h.orientation, h.width, h.height, pixel_bytes,
                            r.y + y0 + k, r.x, r.width, s.row.data());
    emit(s.row.data(), k);
  }
  if (y0 + n_rows >= r.height) {
    s.stored.clear();
    s.stored.shrink_to_fit();
  }
}

StackReader::StackReader(std::vector<fs::path> files, const StackReadOptions& options)
    : impl_(std::make_unique<Impl>()) {
  if (files.empty()) throw Error("capture stack is empty: no images to read");
  impl_->files = std::move(files);
  impl_->sources.resize(impl_->files.size());
  const internal::DecodeSettings settings{.allow_damaged = options.image.allow_damaged};
  for (std::size_t i = 0; i < impl_->files.size(); ++i) {
    const fs::path& f = impl_->files[i];
    impl_->sources[i].decoder = internal::open_decoder(f, settings);
    const internal::Header& h = impl_->sources[i].decoder->header();
    const ImageInfo info = internal::info_from_header(h);
    if (h.format != PixelFormat::kU8) impl_->all_u8 = false;
    if (i == 0) {
      impl_->info = info;
      impl_->channels = sample_channels(h.channels);
      impl_->summary.codec = h.codec;
      continue;
    }
    const ImageInfo& first = impl_->info;
    const std::string first_name = excerpt(impl_->files[0].filename().string());
    if (info.orientation != first.orientation) {
      throw Error(where(f) + ": EXIF orientation " + std::to_string(info.orientation) + " (" +
                  std::string(orientation_name(info.orientation)) + ") but " + first_name +
                  " has " + std::to_string(first.orientation) + " (" +
                  std::string(orientation_name(first.orientation)) +
                  "); every photo of a capture must be taken in the same orientation (the "
                  "camera was turned between shots?)");
    }
    if (info.width != first.width || info.height != first.height) {
      throw Error(where(f) + ": image is " + size_text(info.width, info.height) + " but " +
                  first_name + " is " + size_text(first.width, first.height) +
                  "; every image of a capture must have the same size");
    }
    if (sample_channels(h.channels) != impl_->channels) {
      throw Error(where(f) + ": image has " + std::to_string(sample_channels(h.channels)) +
                  " colour channel(s) but " + first_name + " has " +
                  std::to_string(impl_->channels));
    }
  }
  StackInputSummary& sum = impl_->summary;
  sum.full_width = impl_->info.width;
  sum.full_height = impl_->info.height;
  sum.orientation = impl_->info.orientation;
  PixelRect region{0, 0, sum.full_width, sum.full_height};
  if (options.crop) {
    const PixelRect& c = *options.crop;
    if (c.width < 1 || c.height < 1 || c.x < 0 || c.y < 0 ||
        static_cast<long long>(c.x) + c.width > sum.full_width ||
        static_cast<long long>(c.y) + c.height > sum.full_height) {
      throw Error("crop " + std::to_string(c.x) + "," + std::to_string(c.y) + "," +
                  std::to_string(c.width) + "," + std::to_string(c.height) +
                  " does not lie inside the photos (" + size_text(sum.full_width, sum.full_height) +
                  " as displayed, e.g. " + excerpt(impl_->files[0].filename().string()) + ")");
    }
    region = c;
  }
  if (!options.mask.empty()) {
    const Image mask = read_image(options.mask, options.image);
    if (mask.width() != sum.full_width || mask.height() != sum.full_height) {
      throw Error(where(options.mask) + ": mask is " + size_text(mask.width(), mask.height()) +
                  " but the photos are " + size_text(sum.full_width, sum.full_height) +
                  " (as displayed); the mask must cover the whole photo");
    }
    int x0 = region.x + region.width, y0 = region.y + region.height, x1 = region.x - 1,
        y1 = region.y - 1;
    for (int y = region.y; y < region.y + region.height; ++y) {
      for (int x = region.x; x < region.x + region.width; ++x) {
        if (mask.at(x, y, 0) > 0.5f) {
          x0 = std::min(x0, x);
          x1 = std::max(x1, x);
          y0 = std::min(y0, y);
          y1 = std::max(y1, y);
        }
      }
    }
    if (x1 < x0) {
      throw Error(where(options.mask) + ": the mask selects no pixel" +
                  std::string(options.crop ? " inside the crop" : "") +
                  " (object pixels are those above half of full scale)");
    }
    region = {x0, y0, x1 - x0 + 1, y1 - y0 + 1};
    impl_->mask.resize(static_cast<std::size_t>(region.width) * region.height);
    for (int y = 0; y < region.height; ++y) {
      for (int x = 0; x < region.width; ++x) {
        const bool in = mask.at(region.x + x, region.y + y, 0) > 0.5f;
        impl_->mask[static_cast<std::size_t>(y) * region.width + x] = in ? 1 : 0;
        if (!in) ++sum.masked_out_texels;
      }
    }
    sum.mask = options.mask.string();
  }
  if (options.rows) {
    const RowRange& rr = *options.rows;
    if (rr.begin < 0 || rr.begin >= rr.end || rr.end > region.height) {
      throw Error("rows " + std::to_string(rr.begin) + ".." + std::to_string(rr.end) +
                  " lie outside the " + std::to_string(region.height) + " rows read");
    }
    if (!impl_->mask.empty()) {
      const auto w = static_cast<std::size_t>(region.width);
      std::vector<std::uint8_t> kept(
          impl_->mask.begin() + static_cast<std::ptrdiff_t>(rr.begin * w),
          impl_->mask.begin() + static_cast<std::ptrdiff_t>(rr.end * w));
      impl_->mask.swap(kept);
      sum.masked_out_texels = static_cast<std::uint64_t>(
          std::count(impl_->mask.begin(), impl_->mask.end(), std::uint8_t{0}));
    }
    region.y += rr.begin;
    region.height = rr.rows();
  }
  sum.region = region;
  switch (options.colour_space) {
    case InputColourSpace::kAuto:
      sum.colour_space = impl_->info.colour_space;
      sum.colour_space_source = impl_->info.colour_evidence;
      break;
    case InputColourSpace::kSRGB:
      sum.colour_space = ColourSpace::kSRGB;
      sum.colour_space_source = "--input-colour-space srgb";
      break;
    case InputColourSpace::kLinear:
      sum.colour_space = ColourSpace::kLinear;
      sum.colour_space_source = "--input-colour-space linear";
      break;
  }
  impl_->info.colour_space = sum.colour_space;
  if (options.colour_space != InputColourSpace::kAuto) {
    impl_->info.colour_evidence = sum.colour_space_source;
  }
}

StackReader::~StackReader() = default;

int StackReader::width() const { return impl_->summary.region.width; }
int StackReader::height() const { return impl_->summary.region.height; }
int StackReader::channels() const { return impl_->channels; }
int StackReader::count() const { return static_cast<int>(impl_->files.size()); }
const ImageInfo& StackReader::info() const { return impl_->info; }
const StackInputSummary& StackReader::summary() const { return impl_->summary; }
const std::vector<fs::path>& StackReader::files() const { return impl_->files; }

bool StackReader::read_band(int rows, StackBand* band, BandStorage storage) {
  if (impl_->next_row >= height()) return false;
  if (rows < 1) rows = 1;
  const int y0 = impl_->next_row;
  const int n_rows = std::min(rows, height() - y0);
  band->y0 = y0;
  band->rows = n_rows;
  band->width = width();
  band->channels = channels();
  band->images = count();
  band->is_u8 = storage == BandStorage::kNative8 && impl_->all_u8;
  if (band->is_u8) {
    band->bytes.resize(band->image_stride() * band->images);
    band->samples = {};
  } else {
    band->samples.resize(band->image_stride() * band->images);
    band->bytes = {};
  }

  std::vector<std::string> errors(impl_->sources.size());
  tbb::parallel_for(std::size_t{0}, impl_->sources.size(), [&](std::size_t i) {
    try {
      std::uint8_t* u8 = band->is_u8 ? band->bytes.data() + i * band->image_stride() : nullptr;
      float* f32 = band->is_u8 ? nullptr : band->image(static_cast<int>(i));
      impl_->read_image_rows(i, y0, n_rows, u8, f32);
    } catch (const Error& e) {
      errors[i] = e.what();
    }
  });
  // Report the first failing file in stack order, whatever thread saw it first.
  for (const std::string& e : errors) {
    if (!e.empty()) throw Error(e);
  }
  // Integer files cannot hold NaN; float files can, and one NaN would poison a whole fit.
  if (!band->is_u8) {
    for (int i = 0; i < band->images; ++i) {
      if (impl_->sources[static_cast<std::size_t>(i)].decoder->header().format !=
          PixelFormat::kF32) {
        continue;
      }
      const float* p = band->image(i);
      for (std::size_t k = 0; k < band->image_stride(); ++k) {
        if (!std::isfinite(p[k])) {
          throw Error(where(impl_->files[static_cast<std::size_t>(i)]) +
                      ": NaN or infinite sample in row " +
                      std::to_string(impl_->summary.region.y + y0 +
                                     static_cast<int>(k / (band->width * band->channels))));
        }
      }
    }
  }
  // Texels outside the mask: 0 in every image.
  if (!impl_->mask.empty()) {
    const std::size_t w = static_cast<std::size_t>(band->width);
    const std::size_t ch = static_cast<std::size_t>(band->channels);
    for (int i = 0; i < band->images; ++i) {
      for (int r = 0; r < n_rows; ++r) {
        const std::uint8_t* m = impl_->mask.data() + static_cast<std::size_t>(y0 + r) * w;
        const std::size_t base = band->image_stride() * static_cast<std::size_t>(i) +
                                 static_cast<std::size_t>(r) * w * ch;
        for (std::size_t x = 0; x < w; ++x) {
          if (m[x] != 0) continue;
          for (std::size_t c = 0; c < ch; ++c) {
            if (band->is_u8) {
              band->bytes[base + x * ch + c] = 0;
            } else {
              band->samples[base + x * ch + c] = 0.0f;
            }
          }
        }
      }
    }
  }
  impl_->next_row = y0 + n_rows;
  return true;
}

std::vector<Image> read_stack(const std::vector<fs::path>& files, const StackReadOptions& options) {
  StackReader reader(files, options);
  const std::uint64_t image_bytes = checked_multiply(
      reader.files().front(), static_cast<std::uint64_t>(reader.width()) * reader.height(),
      static_cast<std::uint64_t>(reader.channels()) * sizeof(float));
  check_allocation(reader.files().front(),
                   checked_multiply(reader.files().front(), image_bytes,
                                    static_cast<std::uint64_t>(reader.count())),
                   "the " + std::to_string(reader.count()) + " decoded images");
  std::vector<Image> images;
  images.reserve(files.size());
  for (int i = 0; i < reader.count(); ++i) {
    images.emplace_back(reader.width(), reader.height(), reader.channels(),
                        reader.info().colour_space);
  }
  StackBand band;
  while (reader.read_band(64, &band)) {
    for (int i = 0; i < band.images; ++i) {
      std::copy_n(band.image(i), band.image_stride(),
                  images[static_cast<std::size_t>(i)].row(band.y0));
    }
  }
  return images;
}

int sample_channels(int channels) {
  if (channels == 4 || channels == 2) return channels - 1;
  return std::min(channels, 3);
}

bool read_image_band(const std::vector<Image>& images, int y0, int rows, StackBand* band) {
  if (images.empty()) throw Error("no images");
  const int w = images[0].width();
  const int h = images[0].height();
  const int src_ch = images[0].channels();
  if (y0 >= h) return false;
  for (std::size_t i = 0; i < images.size(); ++i) {
    if (images[i].width() != w || images[i].height() != h || images[i].channels() != src_ch) {
      throw Error("image " + std::to_string(i) + " differs in size or channels from image 0");
    }
  }
  const int ch = sample_channels(src_ch);
  band->y0 = y0;
  band->rows = std::min(rows, h - y0);
  band->width = w;
  band->channels = ch;
  band->images = static_cast<int>(images.size());
  band->is_u8 = false;
  band->bytes.clear();
  band->samples.resize(band->image_stride() * images.size());
  for (std::size_t i = 0; i < images.size(); ++i) {
    float* dst = band->image(static_cast<int>(i));
    for (int r = 0; r < band->rows; ++r) {
      const float* src = images[i].row(y0 + r);
      for (int x = 0; x < w; ++x) {
        for (int c = 0; c < ch; ++c) {
          const float v = src[x * src_ch + c];
          if (!std::isfinite(v)) {
            throw Error("image " + std::to_string(i) + " has a NaN or infinite sample");
          }
          *dst++ = v;
        }
      }
    }
  }
  return true;
}

}  // namespace ptmkit
