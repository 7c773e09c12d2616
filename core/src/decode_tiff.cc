// TIFF through libtiff, for the layouts cameras, raw converters and scanners write: strips,
// interleaved samples, grey or RGB (alpha or extra samples kept as channels), 8- or 16-bit
// unsigned integers or 32-bit floats, any compression libtiff decodes. Other layouts (tiles,
// planar, palette, 1/4-bit, signed, 64-bit, YCbCr, CMYK) go to OpenImageIO.
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <string>

#include <tiffio.h>

#include "decoder.h"
#include "ptmkit/core/error.h"

namespace fs = std::filesystem;

namespace ptmkit::internal {

namespace {

struct TiffMessages {
  std::string error;
};

int on_error(TIFF*, void* user, const char* module, const char* fmt, va_list ap) {
  auto* m = static_cast<TiffMessages*>(user);
  char buf[256];
  std::vsnprintf(buf, sizeof(buf), fmt, ap);
  if (m->error.empty()) m->error = std::string(module != nullptr ? module : "") + ": " + buf;
  return 1;
}

// Warnings are about tags libtiff does not know or ignores; the samples are unaffected.
int on_warning(TIFF*, void*, const char*, const char*, va_list) { return 1; }

class TiffDecoder final : public Decoder {
 public:
  TiffDecoder(fs::path path, const DecodeSettings& settings)
      : path_(std::move(path)), settings_(settings) {}
  ~TiffDecoder() override {
    if (tif_ != nullptr) TIFFClose(tif_);
  }
  TiffDecoder(const TiffDecoder&) = delete;
  TiffDecoder& operator=(const TiffDecoder&) = delete;

  // False: a layout this reader leaves to OpenImageIO.
  bool open(std::uintmax_t file_bytes) {
    TIFFOpenOptions* opts = TIFFOpenOptionsAlloc();
    TIFFOpenOptionsSetErrorHandlerExtR(opts, on_error, &messages_);
    TIFFOpenOptionsSetWarningHandlerExtR(opts, on_warning, &messages_);
    tif_ = TIFFOpenExt(path_.c_str(), "r", opts);
    TIFFOpenOptionsFree(opts);
    if (tif_ == nullptr) {
      throw Error(where(path_) + ": not a readable TIFF: " + excerpt(messages_.error));
    }
    std::uint32_t w = 0, h = 0;
    std::uint16_t spp = 1, bps = 1, fmt = SAMPLEFORMAT_UINT, planar = PLANARCONFIG_CONTIG,
                  photometric = PHOTOMETRIC_MINISBLACK, compression = COMPRESSION_NONE,
                  orientation = ORIENTATION_TOPLEFT;
    TIFFGetField(tif_, TIFFTAG_IMAGEWIDTH, &w);
    TIFFGetField(tif_, TIFFTAG_IMAGELENGTH, &h);
    TIFFGetFieldDefaulted(tif_, TIFFTAG_SAMPLESPERPIXEL, &spp);
    TIFFGetFieldDefaulted(tif_, TIFFTAG_BITSPERSAMPLE, &bps);
    TIFFGetFieldDefaulted(tif_, TIFFTAG_SAMPLEFORMAT, &fmt);
    TIFFGetFieldDefaulted(tif_, TIFFTAG_PLANARCONFIG, &planar);
    TIFFGetField(tif_, TIFFTAG_PHOTOMETRIC, &photometric);
    TIFFGetFieldDefaulted(tif_, TIFFTAG_COMPRESSION, &compression);
    TIFFGetFieldDefaulted(tif_, TIFFTAG_ORIENTATION, &orientation);
    check_dimensions(path_, w, h, spp);
    const bool integer = fmt == SAMPLEFORMAT_UINT && (bps == 8 || bps == 16);
    const bool floats = fmt == SAMPLEFORMAT_IEEEFP && bps == 32;
    const bool layout = !TIFFIsTiled(tif_) && (planar == PLANARCONFIG_CONTIG || spp == 1) &&
                        (photometric == PHOTOMETRIC_MINISBLACK || photometric == PHOTOMETRIC_RGB);
    if (!(integer || floats) || !layout || (photometric == PHOTOMETRIC_RGB && spp < 3)) {
      return false;
    }
    const std::uintmax_t raw = static_cast<std::uintmax_t>(w) * h * spp * (bps / 8);
    if (compression == COMPRESSION_NONE && raw > file_bytes) {
      throw Error(where(path_) + ": declares " + std::to_string(w) + "x" + std::to_string(h) +
                  " uncompressed pixels but the file has only " + std::to_string(file_bytes) +
                  " bytes");
    }
    header_.width = static_cast<int>(w);
    header_.height = static_cast<int>(h);
    header_.channels = spp;
    header_.format = floats ? PixelFormat::kF32 : bps == 16 ? PixelFormat::kU16 : PixelFormat::kU8;
    header_.orientation = orientation >= 1 && orientation <= 8 ? orientation : 1;
    header_.codec = "tiff";
    std::uint32_t icc_bytes = 0;
    void* icc = nullptr;
    if (TIFFGetField(tif_, TIFFTAG_ICCPROFILE, &icc_bytes, &icc) != 0 && icc_bytes > 0) {
      header_.has_colour_metadata = true;
      header_.colour_space = ColourSpace::kSRGB;
      header_.colour_evidence = "ICC profile (taken as sRGB-like encoded)";
    }
    toff_t exif = 0;
    if (TIFFGetField(tif_, TIFFTAG_EXIFIFD, &exif) != 0 && exif != 0) {
      if (TIFFReadEXIFDirectory(tif_, exif) != 0) {
        std::uint16_t cs = 0;
        if (!header_.has_colour_metadata && TIFFGetField(tif_, EXIFTAG_COLORSPACE, &cs) != 0 &&
            cs == 1) {
          header_.has_colour_metadata = true;
          header_.colour_space = ColourSpace::kSRGB;
          header_.colour_evidence = "EXIF ColorSpace sRGB";
        }
        // Rationals come back as float or double, as libtiff stores the field.
        const auto real = [&](ttag_t tag) -> double {
          const TIFFField* field = TIFFFieldWithTag(tif_, tag);
          if (field == nullptr) return 0.0;
          if (TIFFFieldSetGetSize(field) == 8) {
            double v = 0.0;
            return TIFFGetField(tif_, tag, &v) != 0 && std::isfinite(v) ? v : 0.0;
          }
          float v = 0.0f;
          return TIFFGetField(tif_, tag, &v) != 0 && std::isfinite(v) ? v : 0.0;
        };
        ExifFacts facts;
        facts.focal_mm = real(EXIFTAG_FOCALLENGTH);
        facts.focal_plane_x_res = real(EXIFTAG_FOCALPLANEXRESOLUTION);
        std::uint16_t unit = 2, equivalent = 0;
        std::uint32_t recorded = 0;
        if (TIFFGetField(tif_, EXIFTAG_FOCALPLANERESOLUTIONUNIT, &unit) != 0) {
          facts.focal_plane_unit = unit;
        }
        if (TIFFGetField(tif_, EXIFTAG_PIXELXDIMENSION, &recorded) != 0) {
          facts.pixel_x_dimension = recorded;
        }
        if (TIFFGetField(tif_, EXIFTAG_FOCALLENGTHIN35MMFILM, &equivalent) != 0) {
          facts.focal_35mm = equivalent;
        }
        header_.focal_px =
            exif_focal_px(facts, header_.width, header_.height, &header_.focal_evidence);
      }
      if (TIFFSetDirectory(tif_, 0) == 0) {
        throw Error(where(path_) + ": cannot return to the image after its EXIF data");
      }
    }
    messages_.error.clear();
    return true;
  }

  void read_rows(int rows, void* out) override {
    auto* dst = static_cast<unsigned char*>(out);
    const std::size_t stride = row_bytes();
    for (int r = 0; r < rows; ++r) {
      if (next_row_ >= header_.height) throw Error(where(path_) + ": read past the last row");
      if (TIFFReadScanline(tif_, dst + stride * static_cast<std::size_t>(r),
                           static_cast<std::uint32_t>(next_row_), 0) < 0) {
        std::string why = messages_.error.empty() ? "read error" : messages_.error;
        throw Error(where(path_) + ": cannot decode row " + std::to_string(next_row_) + ": " +
                    excerpt(why));
      }
      ++next_row_;
    }
    (void)settings_;
  }

 private:
  fs::path path_;
  DecodeSettings settings_;
  TiffMessages messages_;
  TIFF* tif_ = nullptr;
  int next_row_ = 0;
};

}  // namespace

std::unique_ptr<Decoder> open_tiff(const fs::path& path, std::uintmax_t file_bytes,
                                   const DecodeSettings& settings) {
  auto d = std::make_unique<TiffDecoder>(path, settings);
  if (!d->open(file_bytes)) return nullptr;
  return d;
}

}  // namespace ptmkit::internal
