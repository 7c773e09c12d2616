// ptmkit_oiio: the only code that uses OpenImageIO. Built as a loadable module and opened by
// core (core/src/oiio_client.cc) when a file needs it; see core/src/oiio_bridge.h.
#include <algorithm>
#include <cctype>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>

#include <OpenImageIO/imageio.h>

#include "../src/oiio_bridge.h"

namespace {

void set_error(char* err, std::size_t len, const std::string& msg) {
  if (err == nullptr || len == 0) return;
  std::string m = msg;
  while (!m.empty() && std::isspace(static_cast<unsigned char>(m.back()))) m.pop_back();
  if (m.empty()) m = "unknown image error";
  std::snprintf(err, len, "%s", m.c_str());
}

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return s;
}

struct Reader {
  std::unique_ptr<OIIO::ImageInput> in;
  OIIO::TypeDesc type;
};

OIIO::TypeDesc type_of(int format) {
  if (format == kOiioU8) return OIIO::TypeDesc::UINT8;
  if (format == kOiioU16) return OIIO::TypeDesc::UINT16;
  return OIIO::TypeDesc::FLOAT;
}

void* open_file(const char* path, PtmkitOiioHeader* header, char* err, std::size_t err_len) {
  // Only the reader the extension names: JPEG, PNG and TIFF are recognised by their bytes
  // before this module is asked, and letting OpenImageIO try every reader on an unknown file
  // hands it to each plugin's prober (ffmpeg's among them): seconds for a 24-byte file.
  static const bool extension_only = OIIO::attribute("try_all_readers", 0);
  (void)extension_only;
  // Camera raw: LibRaw's linear output (sRGB primaries, no transfer curve), 16 bits; a fit
  // wants values proportional to the light.
  OIIO::ImageSpec config;
  config.attribute("raw:ColorSpace", "linear");
  auto in = OIIO::ImageInput::open(path, &config);
  if (!in) {
    set_error(err, err_len, OIIO::geterror());
    return nullptr;
  }
  const OIIO::ImageSpec& spec = in->spec();
  if (spec.depth > 1) {
    set_error(err, err_len, "volume images are not supported");
    return nullptr;
  }
  auto r = std::make_unique<Reader>();
  const auto base = spec.format.basetype;
  int format = kOiioF32;
  if (base == OIIO::TypeDesc::UINT8 || base == OIIO::TypeDesc::INT8) format = kOiioU8;
  if (base == OIIO::TypeDesc::UINT16 || base == OIIO::TypeDesc::INT16) format = kOiioU16;
  header->width = spec.width;
  header->height = spec.height;
  header->channels = spec.nchannels;
  header->format = format;
  header->orientation = spec.get_int_attribute("Orientation", 1);
  header->focal_mm = spec.get_float_attribute("Exif:FocalLength", 0.0f);
  header->focal_plane_x_res = spec.get_float_attribute("Exif:FocalPlaneXResolution", 0.0f);
  header->focal_plane_unit = spec.get_int_attribute("Exif:FocalPlaneResolutionUnit", 2);
  header->pixel_x_dimension = spec.get_int_attribute("Exif:PixelXDimension", 0);
  header->focal_35mm = spec.get_int_attribute("Exif:FocalLengthIn35mmFilm", 0);
  const std::string cs = lower(spec.get_string_attribute("oiio:ColorSpace"));
  const std::string fmt = in->format_name();
  header->colour = kOiioColourUnknown;
  if (cs.find("linear") != std::string::npos || fmt == "openexr" || fmt == "raw") {
    header->colour = kOiioColourLinear;
  } else if (cs.find("srgb") != std::string::npos) {
    header->colour = kOiioColourSRGB;
  }
  std::snprintf(header->format_name, sizeof(header->format_name), "%s", fmt.c_str());
  r->type = type_of(format);
  r->in = std::move(in);
  return r.release();
}

int read_rows(void* handle, int y0, int y1, void* out, char* err, std::size_t err_len) {
  auto* r = static_cast<Reader*>(handle);
  const int channels = r->in->spec().nchannels;
  if (!r->in->read_scanlines(0, 0, y0, y1, 0, 0, channels, r->type, out)) {
    set_error(err, err_len, r->in->geterror());
    return 0;
  }
  // Some readers (TIFF strips that cannot be read, for one) log the error, fill the rows and
  // report success.
  if (r->in->has_error()) {
    set_error(err, err_len, r->in->geterror());
    return 2;
  }
  return 1;
}

void close_file(void* handle) {
  auto* r = static_cast<Reader*>(handle);
  if (r == nullptr) return;
  r->in->close();
  delete r;
}

int write_file(const char* type_path, const char* path, int width, int height, int channels,
               int format, const void* pixels, std::ptrdiff_t stride_bytes, int colour,
               int jpeg_quality, const char* const* channel_names, char* err, std::size_t err_len) {
  auto out = OIIO::ImageOutput::create(type_path);
  if (!out) {
    set_error(err, err_len, "cannot write this file type: " + OIIO::geterror());
    return 0;
  }
  const OIIO::TypeDesc type = type_of(format);
  OIIO::ImageSpec spec(width, height, channels, type);
  if (channel_names != nullptr) {
    spec.channelnames.clear();
    for (int i = 0; i < channels; ++i) spec.channelnames.emplace_back(channel_names[i]);
    spec.alpha_channel = -1;
  }
  spec.attribute("oiio:ColorSpace", colour == kOiioColourLinear ? "Linear" : "sRGB");
  const std::string ext = lower(std::filesystem::path(type_path).extension().string());
  if (ext == ".jpg" || ext == ".jpeg") {
    spec.attribute("Compression", "jpeg:" + std::to_string(jpeg_quality));
  }
  if (ext == ".exr") {
    spec.attribute("compression", "zip");
    // Otherwise the writer stamps the current time (capDate): same input, different bytes.
    spec.attribute("DateTime", "");
  }
  if (!out->open(path, spec)) {
    set_error(err, err_len, "cannot open for writing: " + out->geterror());
    return 0;
  }
  const bool ok =
      out->write_image(type, pixels, OIIO::AutoStride, static_cast<OIIO::stride_t>(stride_bytes));
  if (!ok) {
    set_error(err, err_len, "write failed: " + out->geterror());
    out->close();
    return 0;
  }
  if (!out->close()) {
    set_error(err, err_len, "write failed on close: " + out->geterror());
    return 0;
  }
  return 1;
}

const PtmkitOiioApi kApi{PTMKIT_OIIO_ABI, open_file, read_rows, close_file, write_file};

}  // namespace

extern "C" __attribute__((visibility("default"))) const PtmkitOiioApi* ptmkit_oiio_api(void) {
  return &kApi;
}
