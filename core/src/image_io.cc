#include "ptmkit/core/image_io.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include "decoder.h"
#include "encoder.h"
#include "oiio_client.h"
#include "orientation.h"
#include "ptmkit/core/atomic_file.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/limits.h"

namespace fs = std::filesystem;

namespace ptmkit {

std::string_view to_string(PixelFormat format) {
  switch (format) {
    case PixelFormat::kU8:
      return "uint8";
    case PixelFormat::kU16:
      return "uint16";
    case PixelFormat::kF32:
      return "float";
  }
  return "unknown";
}

ImageInfo probe_image(const fs::path& path) {
  return internal::info_from_header(internal::open_decoder(path)->header());
}

namespace {

// Every stored row in the file's own sample type.
std::vector<unsigned char> decode_all(internal::Decoder& d) {
  std::vector<unsigned char> native(d.row_bytes() * static_cast<std::size_t>(d.header().height));
  d.read_rows(d.header().height, native.data());
  return native;
}

// v / 255 or v / 65535 in float, as the stack reader converts (so both give the same bits).
template <class T>
void to_float(const unsigned char* src, std::size_t count, float scale, float* out) {
  const T* p = reinterpret_cast<const T*>(src);
  for (std::size_t k = 0; k < count; ++k) out[k] = static_cast<float>(p[k]) / scale;
}

}  // namespace

Image read_image(const fs::path& path, const ImageReadOptions& options) {
  auto decoder = internal::open_decoder(path, {.allow_damaged = options.allow_damaged});
  const internal::Header& h = decoder->header();
  const ImageInfo info = internal::info_from_header(h);
  const std::uintmax_t pixels = static_cast<std::uintmax_t>(h.width) * h.height * h.channels;
  const std::uintmax_t need = pixels * 4 + decoder->row_bytes() * h.height;
  check_allocation(path, need,
                   "the decoded pixels of this " + std::to_string(info.width) + "x" +
                       std::to_string(info.height) + " image");
  const std::vector<unsigned char> native = decode_all(*decoder);
  Image img(info.width, info.height, info.channels, info.colour_space);
  const std::size_t sample = h.format == PixelFormat::kU8    ? 1
                             : h.format == PixelFormat::kU16 ? 2
                                                             : 4;
  const std::size_t pixel_bytes = sample * static_cast<std::size_t>(h.channels);
  std::vector<unsigned char> row(pixel_bytes * static_cast<std::size_t>(info.width));
  const std::size_t row_samples = static_cast<std::size_t>(info.width) * h.channels;
  for (int y = 0; y < info.height; ++y) {
    const unsigned char* src = native.data() + static_cast<std::size_t>(y) * row.size();
    if (h.orientation != 1) {
      internal::displayed_row(native.data(), h.orientation, h.width, h.height, pixel_bytes, y, 0,
                              info.width, row.data());
      src = row.data();
    }
    float* dst = img.row(y);
    if (h.format == PixelFormat::kU8) {
      to_float<std::uint8_t>(src, row_samples, 255.0f, dst);
    } else if (h.format == PixelFormat::kU16) {
      to_float<std::uint16_t>(src, row_samples, 65535.0f, dst);
    } else {
      std::memcpy(dst, src, row_samples * sizeof(float));
    }
  }
  const auto n = img.size();
  for (std::size_t i = 0; i < n; ++i) {
    if (!std::isfinite(img.data()[i])) {
      throw Error(where(path) + ": image contains NaN or infinite values");
    }
  }
  return img;
}

namespace {

template <class T>
std::vector<T> quantise(ConstImageViewF image, double full_scale) {
  std::vector<T> out(static_cast<std::size_t>(image.width) * image.height * image.channels);
  std::size_t k = 0;
  for (int y = 0; y < image.height; ++y) {
    const float* row = image.row(y);
    for (int i = 0; i < image.width * image.channels; ++i) {
      const double v = std::clamp(static_cast<double>(row[i]), 0.0, 1.0);
      out[k++] = static_cast<T>(std::lround(v * full_scale));
    }
  }
  return out;
}

}  // namespace

namespace {

// Some encoders (PNG, TIFF) do not report a failed write (a full disk, a file size limit):
// the written file is decoded once more before it may replace anything, so a short or
// damaged file is an error rather than an output.
void verify_written_image(const fs::path& temp, const fs::path& shown, int width, int height,
                          int channels) {
  const std::string failed = where(shown) + ": write failed: the written file does not read back";
  Image back;
  try {
    back = read_image(temp);
  } catch (const Error& e) {
    throw Error(failed + " (disk full?): " + e.what());
  }
  if (back.width() != width || back.height() != height || back.channels() != channels) {
    throw Error(failed + " with its size (disk full?)");
  }
}

}  // namespace

void write_image(const fs::path& path, ConstImageViewF image, const ImageWriteOptions& options) {
  if (image.empty()) throw Error(where(path) + ": nothing to write (empty image)");
  for (int y = 0; y < image.height; ++y) {
    const float* row = image.row(y);
    for (int i = 0; i < image.width * image.channels; ++i) {
      if (!std::isfinite(row[i])) {
        throw Error(where(path) + ": refusing to write an image with NaN or infinite values");
      }
    }
  }
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  if ((ext == ".jpg" || ext == ".jpeg") && options.format != PixelFormat::kU8) {
    throw Error(where(path) + ": JPEG holds 8-bit samples only; use .png, .tif or .exr");
  }
  if (ext == ".png" && options.format == PixelFormat::kF32) {
    throw Error(where(path) + ": PNG holds 8- or 16-bit samples only; use .tif or .exr for floats");
  }
  if (!options.channel_names.empty() &&
      options.channel_names.size() != static_cast<std::size_t>(image.channels)) {
    throw Error(where(path) + ": " + std::to_string(options.channel_names.size()) +
                " channel names for " + std::to_string(image.channels) + " channels");
  }
  AtomicOutput out_file(path);
  const void* pixels = image.data;
  std::ptrdiff_t stride_bytes = image.stride * static_cast<std::ptrdiff_t>(sizeof(float));
  std::vector<unsigned char> u8;
  std::vector<unsigned short> u16;
  if (options.format == PixelFormat::kU8) {
    u8 = quantise<unsigned char>(image, 255.0);
    pixels = u8.data();
    stride_bytes = image.width * image.channels;
  } else if (options.format == PixelFormat::kU16) {
    u16 = quantise<unsigned short>(image, 65535.0);
    pixels = u16.data();
    stride_bytes = image.width * image.channels * 2;
  }
  if (ext == ".png") {
    internal::write_png(path, out_file.temp_path(), image.width, image.height, image.channels,
                        options.format == PixelFormat::kU16, pixels, image.colour_space);
  } else if ((ext == ".jpg" || ext == ".jpeg") && (image.channels == 1 || image.channels == 3)) {
    std::vector<unsigned char> exif;
    if (options.exif_camera) {
      const auto& cam = *options.exif_camera;
      if (!(cam.focal_mm > 0.0) || !(cam.sensor_width_mm > 0.0) || !std::isfinite(cam.focal_mm) ||
          !std::isfinite(cam.sensor_width_mm)) {
        throw Error(where(path) +
                    ": the EXIF camera needs a positive focal length and sensor "
                    "width (mm)");
      }
      exif =
          internal::exif_camera_block(cam.focal_mm, cam.sensor_width_mm, image.width, image.height);
    }
    internal::write_jpeg(path, out_file.temp_path(), image.width, image.height, image.channels,
                         u8.data(), std::clamp(options.jpeg_quality, 1, 100), exif);
  } else {
    internal::oiio_write(path, out_file.temp_path(), image.width, image.height, image.channels,
                         options.format, pixels, stride_bytes, image.colour_space,
                         std::clamp(options.jpeg_quality, 1, 100), options.channel_names);
  }
  verify_written_image(out_file.temp_path(), path, image.width, image.height, image.channels);
  out_file.commit();
}

void write_normal_map(const fs::path& path, ConstImageViewF normals) {
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  if (ext == ".exr") {
    write_image(path, normals, {.format = PixelFormat::kF32});
    return;
  }
  Image encoded(normals.width, normals.height, normals.channels, ColourSpace::kLinear);
  for (int y = 0; y < normals.height; ++y) {
    const float* row = normals.row(y);
    for (int i = 0; i < normals.width * normals.channels; ++i) {
      encoded.row(y)[i] = 0.5f * (row[i] + 1.0f);
    }
  }
  write_image(path, encoded.view(), {.format = PixelFormat::kU16});
}

Image read_normal_map(const fs::path& path) {
  const bool stored_as_floats = probe_image(path).format == PixelFormat::kF32;
  Image n = read_image(path);
  if (!stored_as_floats) {
    for (std::size_t i = 0; i < n.size(); ++i) n.data()[i] = 2.0f * n.data()[i] - 1.0f;
  }
  return n;
}

}  // namespace ptmkit
