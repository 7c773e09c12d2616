// The in-memory .ptm (ptm.h): names of versions and formats, the PtmFile byte layout and its
// values. The header text, reading and writing are ptm_header.cc, ptm_read.cc, ptm_write.cc.
#include "ptmkit/texture/ptm.h"

#include <algorithm>
#include <cstdint>

#include "ptm_internal.h"
#include "ptmkit/core/colour.h"

namespace ptmkit::texture {

std::string_view to_string(PtmVersion version) {
  return version == PtmVersion::k1_1 ? "PTM_1.1" : "PTM_1.2";
}

std::string_view to_string(PtmFormat format) {
  return format == PtmFormat::kRGB ? "PTM_FORMAT_RGB" : "PTM_FORMAT_LRGB";
}

std::string_view format_name(PtmFormat format, PtmCompression compression) {
  if (compression == PtmCompression::kJpeg) {
    return format == PtmFormat::kRGB ? "PTM_FORMAT_JPEG_RGB" : "PTM_FORMAT_JPEG_LRGB";
  }
  return to_string(format);
}

int PtmInfo::bytes_per_texel() const {
  return luminance_only ? kPtmTerms : internal::bytes_per_texel(format);
}

std::string_view PtmInfo::format_line() const {
  return luminance_only ? "PTM_FORMAT_LUM" : format_name(format, compression);
}

// ---------------------------------------------------------------------------------------------
// PtmFile

namespace internal {

std::size_t coeff_offset(const PtmFile& f, int x, int y, int plane, int term) {
  const std::size_t stored_row = static_cast<std::size_t>(f.height - 1 - y);
  const std::size_t pixel = stored_row * f.width + x;
  if (f.version == PtmVersion::k1_1) return pixel * 9 + term;
  return static_cast<std::size_t>(plane) * f.texels() * kPtmTerms + pixel * kPtmTerms + term;
}

std::size_t rgb_offset(const PtmFile& f, int x, int y, int channel) {
  const std::size_t stored_row = static_cast<std::size_t>(f.height - 1 - y);
  const std::size_t pixel = stored_row * f.width + x;
  if (f.version == PtmVersion::k1_1) return pixel * 9 + kPtmTerms + channel;
  return f.texels() * kPtmTerms + pixel * 3 + channel;
}

void file_relit(const PtmFile& f, int x, int y, double lu, double lv, float rgb[3]) {
  const auto basis = ptm_basis(lu, lv);
  const auto& q = f.quantisation;
  auto poly = [&](int plane) {
    double v = 0.0;
    for (int i = 0; i < kPtmTerms; ++i) {
      v += static_cast<double>(q.scales[i]) *
           (f.data[coeff_offset(f, x, y, plane, i)] - q.biases[i]) * basis[i];
    }
    return v;  // file units
  };
  if (f.format == PtmFormat::kRGB) {
    for (int c = 0; c < 3; ++c) rgb[c] = static_cast<float>(poly(c) / 255.0);
  } else {
    const double l = poly(0) / 255.0;
    for (int c = 0; c < 3; ++c) {
      rgb[c] = static_cast<float>(l * f.data[rgb_offset(f, x, y, c)] / 255.0);
    }
  }
}

void file_polynomials(ColourModel model, const float* a, const float* colour, float* polys,
                      std::uint8_t* rgb) {
  switch (model) {
    case ColourModel::kRGB:
      std::copy_n(a, 3 * kPtmTerms, polys);
      break;
    case ColourModel::kLRGB:
      std::copy_n(a, kPtmTerms, polys);
      for (int c = 0; c < 3; ++c) rgb[c] = colour_byte(colour[c]);
      break;
    case ColourModel::kYCC: {
      // Linear in (y, cb, cr): a0..a4 carry no chroma, a5 carries all of it.
      for (int i = 0; i < kPtmTerms; ++i) {
        const bool constant = i == kPtmTerms - 1;
        double r = 0, g = 0, b = 0;
        from_ycbcr({a[i], constant ? colour[0] : 0.0, constant ? colour[1] : 0.0}, &r, &g, &b);
        polys[i] = static_cast<float>(r);
        polys[kPtmTerms + i] = static_cast<float>(g);
        polys[2 * kPtmTerms + i] = static_cast<float>(b);
      }
      break;
    }
  }
}

}  // namespace internal

using internal::coeff_offset;
using internal::rgb_offset;

std::uint8_t PtmFile::coeff_byte(int x, int y, int plane, int term) const {
  return data[coeff_offset(*this, x, y, plane, term)];
}

std::uint8_t PtmFile::rgb_byte(int x, int y, int channel) const {
  return data[rgb_offset(*this, x, y, channel)];
}

double PtmFile::coefficient(int x, int y, int plane, int term) const {
  return static_cast<double>(quantisation.scales[term]) *
         (coeff_byte(x, y, plane, term) - quantisation.biases[term]);
}

}  // namespace ptmkit::texture
