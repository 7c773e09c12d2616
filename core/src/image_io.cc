#include "ptmkit/core/image_io.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <string>
#include <vector>

#include <OpenImageIO/imageio.h>

#include "internal_oiio.h"
#include "ptmkit/core/atomic_file.h"
#include "ptmkit/core/error.h"

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

namespace internal {

std::string oiio_error(const OIIO::ImageInput* in) {
  std::string msg = in != nullptr ? in->geterror() : OIIO::geterror();
  if (msg.empty()) msg = OIIO::geterror();
  while (!msg.empty() && std::isspace(static_cast<unsigned char>(msg.back()))) msg.pop_back();
  return msg.empty() ? "unknown image error" : msg;
}

std::unique_ptr<OIIO::ImageInput> open_input(const fs::path& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) throw Error(where(path) + ": image file not found");
  if (!fs::is_regular_file(path, ec)) throw Error(where(path) + ": not a regular file");
  auto in = OIIO::ImageInput::open(path.string());
  if (!in) throw Error(where(path) + ": cannot read image: " + oiio_error(nullptr));
  const auto& spec = in->spec();
  if (spec.width <= 0 || spec.height <= 0 || spec.nchannels <= 0) {
    throw Error(where(path) + ": image has no pixels");
  }
  if (spec.depth > 1) throw Error(where(path) + ": volume images are not supported");
  return in;
}

ImageInfo info_from_spec(const OIIO::ImageSpec& spec) {
  ImageInfo info;
  info.width = spec.width;
  info.height = spec.height;
  info.channels = spec.nchannels;
  const auto base = spec.format.basetype;
  if (base == OIIO::TypeDesc::UINT8 || base == OIIO::TypeDesc::INT8) {
    info.format = PixelFormat::kU8;
  } else if (base == OIIO::TypeDesc::UINT16 || base == OIIO::TypeDesc::INT16) {
    info.format = PixelFormat::kU16;
  } else {
    info.format = PixelFormat::kF32;
  }
  std::string cs = spec.get_string_attribute("oiio:ColorSpace");
  std::transform(cs.begin(), cs.end(), cs.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  if (cs.find("linear") != std::string::npos) {
    info.colour_space = ColourSpace::kLinear;
  } else if (cs.find("srgb") != std::string::npos) {
    info.colour_space = ColourSpace::kSRGB;
  } else {
    info.colour_space =
        info.format == PixelFormat::kF32 ? ColourSpace::kLinear : ColourSpace::kSRGB;
  }
  return info;
}

}  // namespace internal

ImageInfo probe_image(const fs::path& path) {
  auto in = internal::open_input(path);
  ImageInfo info = internal::info_from_spec(in->spec());
  in->close();
  return info;
}

Image read_image(const fs::path& path) {
  auto in = internal::open_input(path);
  const ImageInfo info = internal::info_from_spec(in->spec());
  Image img(info.width, info.height, info.channels, info.colour_space);
  if (!in->read_image(0, 0, 0, info.channels, OIIO::TypeDesc::FLOAT, img.data())) {
    throw Error(where(path) + ": cannot decode image: " + internal::oiio_error(in.get()));
  }
  in->close();
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
void verify_written_image(const fs::path& temp, const fs::path& shown,
                          const OIIO::ImageSpec& want) {
  auto in = OIIO::ImageInput::open(temp.string());
  const std::string failed = where(shown) + ": write failed: the written file does not read back";
  if (!in) throw Error(failed + " (disk full?): " + internal::oiio_error(nullptr));
  const OIIO::ImageSpec& got = in->spec();
  if (got.width != want.width || got.height != want.height || got.nchannels != want.nchannels) {
    throw Error(failed + " with its size (disk full?)");
  }
  std::vector<unsigned char> buf(got.image_bytes());
  const bool ok = in->read_image(0, 0, 0, got.nchannels, got.format, buf.data());
  const bool error = in->has_error();
  const std::string message = error ? in->geterror() : std::string();
  in->close();
  if (!ok || error) throw Error(failed + " (disk full?): " + message);
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
  AtomicOutput out_file(path);
  auto out = OIIO::ImageOutput::create(path.string());
  if (!out) {
    throw Error(where(path) + ": cannot write this file type: " + internal::oiio_error(nullptr));
  }
  OIIO::TypeDesc type = OIIO::TypeDesc::UINT8;
  if (options.format == PixelFormat::kU16) type = OIIO::TypeDesc::UINT16;
  if (options.format == PixelFormat::kF32) type = OIIO::TypeDesc::FLOAT;
  OIIO::ImageSpec spec(image.width, image.height, image.channels, type);
  spec.attribute("oiio:ColorSpace", image.colour_space == ColourSpace::kLinear ? "Linear" : "sRGB");
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  if (ext == ".jpg" || ext == ".jpeg") {
    if (options.format != PixelFormat::kU8) {
      throw Error(where(path) + ": JPEG holds 8-bit samples only; use .png, .tif or .exr");
    }
    spec.attribute("Compression",
                   "jpeg:" + std::to_string(std::clamp(options.jpeg_quality, 1, 100)));
  }
  if (ext == ".exr") {
    spec.attribute("compression", "zip");
    // Otherwise the writer stamps the current time (capDate): same input, different bytes.
    spec.attribute("DateTime", "");
  }
  if (!out->open(out_file.temp_path().string(), spec)) {
    throw Error(where(path) + ": cannot open for writing: " + out->geterror());
  }
  bool ok = false;
  if (options.format == PixelFormat::kU8) {
    auto buf = quantise<unsigned char>(image, 255.0);
    ok = out->write_image(OIIO::TypeDesc::UINT8, buf.data());
  } else if (options.format == PixelFormat::kU16) {
    auto buf = quantise<unsigned short>(image, 65535.0);
    ok = out->write_image(OIIO::TypeDesc::UINT16, buf.data());
  } else {
    ok = out->write_image(OIIO::TypeDesc::FLOAT, image.data, OIIO::AutoStride,
                          static_cast<OIIO::stride_t>(image.stride * sizeof(float)));
  }
  if (!ok) throw Error(where(path) + ": write failed: " + out->geterror());
  if (!out->close()) throw Error(where(path) + ": write failed: " + out->geterror());
  verify_written_image(out_file.temp_path(), path, spec);
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
