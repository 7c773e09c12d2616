#include "ptmkit/core/stack_reader.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <string>

#include <tbb/parallel_for.h>

#include "internal_oiio.h"
#include "ptmkit/core/error.h"

namespace fs = std::filesystem;

namespace ptmkit {

namespace {

int colour_channels(const OIIO::ImageSpec& spec) { return sample_channels(spec.nchannels); }

}  // namespace

namespace {

// Decoding straight to float through OpenImageIO runs its generic per-sample converter, which
// cost more than the JPEG decoding itself (measured: 29% of a whole fit's CPU). Integer files
// are read in their own type and converted here: a table for 8-bit (the same values, v / 255),
// a division for 16-bit.
const std::array<float, 256>& u8_to_float() {
  static const std::array<float, 256> table = [] {
    std::array<float, 256> t{};
    for (int v = 0; v < 256; ++v) t[static_cast<std::size_t>(v)] = static_cast<float>(v) / 255.0f;
    return t;
  }();
  return table;
}

// Rows [y0, y1) in the file's own sample type. OpenImageIO's read_scanlines allocates (and
// frees) a 64 MiB staging buffer on every call; at 49 images x 375 bands that was 18 000
// mmap/munmap pairs whose TLB shootdowns cost a quarter of a 12 MP fit's CPU. When the file's
// layout is already what the band wants (scanline file, one sample type, every channel), the
// native reader fills our buffer directly.
bool read_rows_native(OIIO::ImageInput& in, int y0, int y1, int channels, OIIO::TypeDesc type,
                      void* out) {
  const auto& spec = in.spec();
  if (spec.tile_width == 0 && spec.channelformats.empty() && spec.nchannels == channels &&
      spec.format == type) {
    const OIIO::ImageInput::lock_guard guard(in);
    return in.read_native_scanlines(0, 0, y0, y1, 0, out);
  }
  return in.read_scanlines(0, 0, y0, y1, 0, 0, channels, type, out);
}

bool read_rows_as_float(OIIO::ImageInput& in, int y0, int y1, int channels,
                        std::vector<unsigned char>* scratch, float* out) {
  const std::size_t count =
      static_cast<std::size_t>(y1 - y0) * static_cast<std::size_t>(in.spec().width) * channels;
  const auto base = in.spec().format.basetype;
  if (base == OIIO::TypeDesc::UINT8) {
    scratch->resize(count);
    if (!read_rows_native(in, y0, y1, channels, OIIO::TypeDesc::UINT8, scratch->data())) {
      return false;
    }
    const auto& table = u8_to_float();
    const unsigned char* src = scratch->data();
    for (std::size_t k = 0; k < count; ++k) out[k] = table[src[k]];
    return true;
  }
  if (base == OIIO::TypeDesc::UINT16) {
    scratch->resize(count * 2);
    if (!read_rows_native(in, y0, y1, channels, OIIO::TypeDesc::UINT16, scratch->data())) {
      return false;
    }
    const auto* src = reinterpret_cast<const std::uint16_t*>(scratch->data());
    for (std::size_t k = 0; k < count; ++k) out[k] = static_cast<float>(src[k]) / 65535.0f;
    return true;
  }
  return read_rows_native(in, y0, y1, channels, OIIO::TypeDesc::FLOAT, out);
}

}  // namespace

struct StackReader::Impl {
  std::vector<fs::path> files;
  std::vector<std::unique_ptr<OIIO::ImageInput>> inputs;
  std::vector<std::vector<unsigned char>> scratch;  // per image: native samples of a band
  ImageInfo info;
  int channels = 0;
  int next_row = 0;
};

StackReader::StackReader(std::vector<fs::path> files) : impl_(std::make_unique<Impl>()) {
  if (files.empty()) throw Error("capture stack is empty: no images to read");
  impl_->files = std::move(files);
  impl_->inputs.resize(impl_->files.size());
  impl_->scratch.resize(impl_->files.size());
  for (std::size_t i = 0; i < impl_->files.size(); ++i) {
    const fs::path& f = impl_->files[i];
    impl_->inputs[i] = internal::open_input(f);
    const auto& spec = impl_->inputs[i]->spec();
    if (i == 0) {
      impl_->info = internal::info_from_spec(spec);
      impl_->channels = colour_channels(spec);
      continue;
    }
    const ImageInfo& first = impl_->info;
    if (spec.width != first.width || spec.height != first.height) {
      throw Error(where(f) + ": image is " + std::to_string(spec.width) + "x" +
                  std::to_string(spec.height) + " but " + impl_->files[0].filename().string() +
                  " is " + std::to_string(first.width) + "x" + std::to_string(first.height) +
                  "; every image of a capture must have the same size");
    }
    if (colour_channels(spec) != impl_->channels) {
      throw Error(where(f) + ": image has " + std::to_string(colour_channels(spec)) +
                  " colour channel(s) but " + impl_->files[0].filename().string() + " has " +
                  std::to_string(impl_->channels));
    }
  }
}

StackReader::~StackReader() = default;

int StackReader::width() const { return impl_->info.width; }
int StackReader::height() const { return impl_->info.height; }
int StackReader::channels() const { return impl_->channels; }
int StackReader::count() const { return static_cast<int>(impl_->files.size()); }
const ImageInfo& StackReader::info() const { return impl_->info; }
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
  band->is_u8 = storage == BandStorage::kNative8 && impl_->info.format == PixelFormat::kU8;
  if (band->is_u8) {
    band->bytes.resize(band->image_stride() * band->images);
    band->samples = {};
  } else {
    band->samples.resize(band->image_stride() * band->images);
    band->bytes = {};
  }

  std::vector<std::string> errors(impl_->inputs.size());
  tbb::parallel_for(std::size_t{0}, impl_->inputs.size(), [&](std::size_t i) {
    auto& in = impl_->inputs[i];
    const bool ok =
        band->is_u8 ? read_rows_native(*in, y0, y0 + n_rows, band->channels, OIIO::TypeDesc::UINT8,
                                       band->bytes.data() + i * band->image_stride())
                    : read_rows_as_float(*in, y0, y0 + n_rows, band->channels, &impl_->scratch[i],
                                         band->image(static_cast<int>(i)));
    if (!ok) errors[i] = internal::oiio_error(in.get());
  });
  // Report the first failing file in stack order, whatever thread saw it first.
  for (std::size_t i = 0; i < errors.size(); ++i) {
    if (!errors[i].empty()) {
      throw Error(where(impl_->files[i]) + ": cannot decode rows " + std::to_string(y0) + ".." +
                  std::to_string(y0 + n_rows - 1) + ": " + errors[i]);
    }
  }
  // Integer files cannot hold NaN; float files can, and one NaN would poison a whole fit.
  if (impl_->info.format == PixelFormat::kF32) {
    for (int i = 0; i < band->images; ++i) {
      const float* p = band->image(i);
      for (std::size_t k = 0; k < band->image_stride(); ++k) {
        if (!std::isfinite(p[k])) {
          throw Error(where(impl_->files[i]) + ": NaN or infinite sample in row " +
                      std::to_string(y0 + static_cast<int>(k / (band->width * band->channels))));
        }
      }
    }
  }
  impl_->next_row = y0 + n_rows;
  return true;
}

std::vector<Image> read_stack(const std::vector<fs::path>& files) {
  StackReader reader(files);
  std::vector<Image> images;
  images.reserve(files.size());
  for (int i = 0; i < reader.count(); ++i) {
    images.emplace_back(reader.width(), reader.height(), reader.channels(),
                        reader.info().colour_space);
  }
  StackBand band;
  while (reader.read_band(64, &band)) {
    for (int i = 0; i < band.images; ++i) {
      std::copy_n(band.image(i), band.image_stride(), images[i].row(band.y0));
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
