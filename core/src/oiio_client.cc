// Loads the ptmkit_oiio module on first use and adapts it to core's Decoder and writer.
#include <dlfcn.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cstring>
#include <mutex>
#include <string>
#include <vector>

#include "decoder.h"
#include "oiio_bridge.h"
#include "oiio_client.h"
#include "ptmkit/core/error.h"

namespace fs = std::filesystem;

namespace ptmkit::internal {

namespace {

// Where the module may be: $PTMKIT_OIIO_MODULE, beside the executable, ../lib/ptmkit from
// it (an installed tree), and where the build put it.
std::vector<fs::path> module_candidates() {
  std::vector<fs::path> out;
  if (const char* env = std::getenv("PTMKIT_OIIO_MODULE"); env != nullptr && *env != '\0') {
    out.emplace_back(env);
    return out;
  }
  std::array<char, 4096> exe{};
  const ssize_t n = readlink("/proc/self/exe", exe.data(), exe.size() - 1);
  if (n > 0) {
    const fs::path dir =
        fs::path(std::string(exe.data(), static_cast<std::size_t>(n))).parent_path();
    out.push_back(dir / "libptmkit_oiio.so");
    out.push_back(dir / ".." / "lib" / "ptmkit" / "libptmkit_oiio.so");
  }
#ifdef PTMKIT_OIIO_MODULE_BUILD_PATH
  out.emplace_back(PTMKIT_OIIO_MODULE_BUILD_PATH);
#endif
  return out;
}

const PtmkitOiioApi* load_api(std::string* why) {
  static std::once_flag once;
  static const PtmkitOiioApi* api = nullptr;
  static std::string error;
  std::call_once(once, [] {
    std::string tried;
    for (const fs::path& p : module_candidates()) {
      std::error_code ec;
      if (!fs::exists(p, ec)) {
        tried += (tried.empty() ? "" : ", ") + p.string();
        continue;
      }
      void* handle = dlopen(p.c_str(), RTLD_NOW | RTLD_LOCAL);
      if (handle == nullptr) {
        const char* e = dlerror();
        error = "cannot load " + p.string() + ": " + (e != nullptr ? e : "unknown error");
        return;
      }
      using Fn = const PtmkitOiioApi* (*)();
      auto fn = reinterpret_cast<Fn>(dlsym(handle, "ptmkit_oiio_api"));
      if (fn == nullptr || fn() == nullptr || fn()->abi != PTMKIT_OIIO_ABI) {
        error = p.string() + " is not a ptmkit_oiio module of this version";
        return;
      }
      api = fn();
      return;
    }
    error = "the OpenImageIO module (libptmkit_oiio.so) was not found (looked at " + tried +
            "; set PTMKIT_OIIO_MODULE to its path)";
  });
  if (api == nullptr && why != nullptr) *why = error;
  return api;
}

class OiioDecoder final : public Decoder {
 public:
  OiioDecoder(fs::path path, const PtmkitOiioApi* api, void* handle, DecodeSettings settings)
      : path_(std::move(path)), api_(api), handle_(handle), settings_(settings) {}
  ~OiioDecoder() override { api_->close(handle_); }
  OiioDecoder(const OiioDecoder&) = delete;
  OiioDecoder& operator=(const OiioDecoder&) = delete;
  Header& header() { return header_; }

  // OpenImageIO's read_scanlines allocates a 64 MiB conversion buffer on each call, whatever
  // the number of rows: a tall narrow image read in bands of 64 rows paid for that thousands
  // of times (a 8 x 65528 TIFF took 23 s under the sanitizers). Rows are therefore read at
  // least kChunkBytes at a time and handed out from here.
  void read_rows(int rows, void* out) override {
    if (next_row_ + rows > header_.height) throw Error(where(path_) + ": read past the last row");
    auto* dst = static_cast<unsigned char*>(out);
    const std::size_t stride = row_bytes();
    while (rows > 0) {
      if (chunk_next_ == chunk_rows_) {
        const int left = header_.height - decoded_row_;
        const int want = static_cast<int>(
            std::min<std::size_t>(left, std::max<std::size_t>(1, kChunkBytes / stride)));
        if (rows >= want) {  // a large request goes straight to the caller
          decode(rows, dst);
          next_row_ += rows;
          return;
        }
        chunk_.resize(stride * static_cast<std::size_t>(want));
        decode(want, chunk_.data());
        chunk_rows_ = want;
        chunk_next_ = 0;
      }
      const int n = std::min(rows, chunk_rows_ - chunk_next_);
      std::memcpy(dst, chunk_.data() + stride * static_cast<std::size_t>(chunk_next_),
                  stride * static_cast<std::size_t>(n));
      dst += stride * static_cast<std::size_t>(n);
      chunk_next_ += n;
      next_row_ += n;
      rows -= n;
    }
  }

 private:
  static constexpr std::size_t kChunkBytes = std::size_t{1} << 20;

  // Decodes the next `rows` rows of the file into `out`.
  void decode(int rows, unsigned char* out) {
    char err[512] = {};
    const int status =
        api_->read_rows(handle_, decoded_row_, decoded_row_ + rows, out, err, sizeof(err));
    if (status == 0) {
      throw Error(where(path_) + ": cannot decode rows " + std::to_string(decoded_row_) + ".." +
                  std::to_string(decoded_row_ + rows - 1) + ": " + excerpt(err));
    }
    if (status == 2) damaged_data(path_, settings_, err, &warned_);
    decoded_row_ += rows;
  }

  fs::path path_;
  const PtmkitOiioApi* api_;
  void* handle_;
  DecodeSettings settings_;
  bool warned_ = false;
  int next_row_ = 0;     // the next row handed out
  int decoded_row_ = 0;  // the next row to decode
  std::vector<unsigned char> chunk_;
  int chunk_rows_ = 0;
  int chunk_next_ = 0;
};

}  // namespace

bool oiio_available() { return load_api(nullptr) != nullptr; }

std::unique_ptr<Decoder> open_oiio(const fs::path& path, const DecodeSettings& settings) {
  std::string why;
  const PtmkitOiioApi* api = load_api(&why);
  if (api == nullptr) {
    throw Error(where(path) + ": not a JPEG, PNG or TIFF file, and " + why);
  }
  PtmkitOiioHeader h{};
  char err[512] = {};
  void* handle = api->open(path.c_str(), &h, err, sizeof(err));
  if (handle == nullptr) throw Error(where(path) + ": cannot read image: " + excerpt(err));
  auto d = std::make_unique<OiioDecoder>(path, api, handle, settings);
  check_dimensions(path, h.width, h.height, h.channels);
  Header& header = d->header();
  header.width = h.width;
  header.height = h.height;
  header.channels = h.channels;
  header.format = h.format == kOiioU8    ? PixelFormat::kU8
                  : h.format == kOiioU16 ? PixelFormat::kU16
                                         : PixelFormat::kF32;
  header.orientation = h.orientation >= 1 && h.orientation <= 8 ? h.orientation : 1;
  ExifFacts exif;
  exif.focal_mm = h.focal_mm;
  exif.focal_plane_x_res = h.focal_plane_x_res;
  exif.focal_plane_unit = h.focal_plane_unit;
  exif.pixel_x_dimension = h.pixel_x_dimension;
  exif.focal_35mm = h.focal_35mm;
  header.focal_px = exif_focal_px(exif, h.width, h.height, &header.focal_evidence);
  header.codec = std::string("oiio:") + h.format_name;
  if (h.colour != kOiioColourUnknown) {
    header.has_colour_metadata = true;
    header.colour_space = h.colour == kOiioColourLinear ? ColourSpace::kLinear : ColourSpace::kSRGB;
    header.colour_evidence = std::string(h.format_name) + " metadata";
  }
  return d;
}

void oiio_write(const fs::path& type_path, const fs::path& path, int width, int height,
                int channels, PixelFormat format, const void* pixels, std::ptrdiff_t stride_bytes,
                ColourSpace colour, int jpeg_quality,
                const std::vector<std::string>& channel_names) {
  std::string why;
  const PtmkitOiioApi* api = load_api(&why);
  if (api == nullptr) throw Error(where(type_path) + ": cannot write this file type: " + why);
  std::vector<const char*> names;
  for (const auto& n : channel_names) names.push_back(n.c_str());
  char err[512] = {};
  const int f = format == PixelFormat::kU8    ? kOiioU8
                : format == PixelFormat::kU16 ? kOiioU16
                                              : kOiioF32;
  if (api->write(type_path.c_str(), path.c_str(), width, height, channels, f, pixels, stride_bytes,
                 colour == ColourSpace::kLinear ? kOiioColourLinear : kOiioColourSRGB, jpeg_quality,
                 names.empty() ? nullptr : names.data(), err, sizeof(err)) == 0) {
    throw Error(where(type_path) + ": " + excerpt(err));
  }
}

}  // namespace ptmkit::internal
