#include "ptmkit/texture/convert.h"

#include <cstdio>
#include <system_error>

#include "ptm_internal.h"
#include "ptmkit/core/error.h"
#include "ptmkit/texture/rti.h"
#include "ptmkit/texture/texture_file.h"
#include "ptmkit/texture/web_folder.h"

namespace fs = std::filesystem;

namespace ptmkit::texture {

namespace {

struct Target {
  bool same = true;
  PtmFormat format = PtmFormat::kRGB;
  PtmCompression compression = PtmCompression::kNone;
};

Target parse_target(const std::string& name) {
  Target t;
  if (name.empty()) return t;
  t.same = false;
  if (name == "rgb") {
    t.format = PtmFormat::kRGB;
  } else if (name == "lrgb") {
    t.format = PtmFormat::kLRGB;
  } else if (name == "jpeg-rgb") {
    t.format = PtmFormat::kRGB;
    t.compression = PtmCompression::kJpeg;
  } else if (name == "jpeg-lrgb") {
    t.format = PtmFormat::kLRGB;
    t.compression = PtmCompression::kJpeg;
  } else {
    throw Error("--format '" + name + "': expected rgb, lrgb, jpeg-rgb or jpeg-lrgb");
  }
  return t;
}

[[noreturn]] void refuse(const fs::path& input, const std::string& from, const std::string& to,
                         const std::string& why) {
  throw Error(where(input) + ": " + from + " -> " + to + " is refused: " + why);
}

// The same file's bytes in the PTM 1.2 layout (a 1.1 file interleaves its nine bytes).
PtmFile as_1_2(const PtmFile& f) {
  if (f.version == PtmVersion::k1_2) return f;
  PtmFile g = f;
  g.version = PtmVersion::k1_2;
  g.header.clear();
  for (int y = 0; y < f.height; ++y) {
    for (int x = 0; x < f.width; ++x) {
      for (int t = 0; t < kPtmTerms; ++t) {
        g.data[internal::coeff_offset(g, x, y, 0, t)] = f.coeff_byte(x, y, 0, t);
      }
      for (int c = 0; c < 3; ++c) g.data[internal::rgb_offset(g, x, y, c)] = f.rgb_byte(x, y, c);
    }
  }
  return g;
}

// An LRGB map as three RGB polynomials (luminance x colour channel).
CoefficientMap lrgb_to_rgb(const CoefficientMap& m) {
  CoefficientMap out(m.width, m.height, ColourModel::kRGB, m.colour_space);
  for (int y = 0; y < m.height; ++y) {
    for (int x = 0; x < m.width; ++x) {
      const float* a = m.texel_coeffs(x, y);
      const float* col = m.texel_colour(x, y);
      float* b = out.texel_coeffs(x, y);
      for (int c = 0; c < 3; ++c) {
        for (int t = 0; t < kPtmTerms; ++t) b[c * kPtmTerms + t] = a[t] * col[c];
      }
    }
  }
  return out;
}

std::string describe(const PtmWriteReport& r) { return r.brief(); }

}  // namespace

ConvertReport convert_to_ptm(const fs::path& input, const fs::path& output,
                             const ConvertOptions& options) {
  const Target target = parse_target(options.ptm_format);
  if (options.jpeg_quality < 0 || options.jpeg_quality > 100) {
    throw Error("JPEG quality " + std::to_string(options.jpeg_quality) + " is not in 1..100");
  }
  ConvertReport report;
  report.input = input;
  report.output = output;
  const TextureSource source = detect_texture_source(input);
  PtmFile out;
  if (source == TextureSource::kPtm) {
    const PtmFile in = read_ptm_file(input);
    report.from =
        in.luminance_only ? "PTM_FORMAT_LUM" : std::string(format_name(in.format, in.compression));
    const PtmFormat format = target.same ? in.format : target.format;
    const PtmCompression compression = target.same ? in.compression : target.compression;
    const std::string to(format_name(format, compression));
    if (in.format == PtmFormat::kRGB && format == PtmFormat::kLRGB) {
      refuse(input, report.from, to,
             "one luminance polynomial times a colour cannot hold three independent RGB "
             "polynomials");
    }
    if (format == in.format && options.write.integer_scales) {
      // Re-quantised with whole-number scales (for truncating readers).
      const CoefficientMap m = decode_ptm(in);
      PtmWriteReport q;
      out = encode_ptm(m, options.write, &q);
      report.quantisation = describe(q);
    } else if (format == in.format) {
      out = as_1_2(in);
      out.header = in.version == PtmVersion::k1_2 && in.compression == compression &&
                           compression == PtmCompression::kNone
                       ? in.header
                       : std::string();
      out.trailing =
          compression == PtmCompression::kNone ? in.trailing : std::vector<std::uint8_t>();
      report.bytes_kept = true;
    } else {  // LRGB -> RGB
      PtmWriteReport q;
      out = encode_ptm(lrgb_to_rgb(decode_ptm(in)), options.write, &q);
      report.quantisation = describe(q);
    }
    out.compression = compression;
    out.compression_parameter = options.jpeg_quality > 0                  ? options.jpeg_quality
                                : in.compression == PtmCompression::kJpeg ? in.compression_parameter
                                                                          : 90;
  } else {
    const LoadedTexture tex = read_texture(input);
    report.from = tex.format;
    if (tex.is_hsh) {
      refuse(input, report.from, "PTM",
             "the six-term polynomial cannot hold an HSH basis (the conversion is lossy)");
    }
    const PtmFormat own = tex.ptm.model == ColourModel::kLRGB ? PtmFormat::kLRGB : PtmFormat::kRGB;
    const PtmFormat format = target.same ? own : target.format;
    const PtmCompression compression = target.same ? PtmCompression::kNone : target.compression;
    if (own == PtmFormat::kRGB && format == PtmFormat::kLRGB) {
      refuse(input, report.from, std::string(format_name(format, compression)),
             "one luminance polynomial times a colour cannot hold three independent RGB "
             "polynomials");
    }
    PtmWriteReport q;
    out = encode_ptm(format == own ? tex.ptm : lrgb_to_rgb(tex.ptm), options.write, &q);
    report.quantisation = describe(q);
    out.compression = compression;
    out.compression_parameter = options.jpeg_quality > 0 ? options.jpeg_quality : 90;
  }
  report.to = std::string(format_name(out.format, out.compression));
  report.file_bytes = write_ptm_file(output, out);
  return report;
}

ConvertReport convert_to_rti(const fs::path& input, const fs::path& output,
                             const ConvertOptions& options) {
  if (!options.ptm_format.empty()) {
    throw Error("--format applies to export ptm only (an .rti has one format)");
  }
  ConvertReport report;
  report.input = input;
  report.output = output;
  const LoadedTexture tex = read_texture(input);
  report.from = tex.format;
  report.to = "RTI HSH " + std::to_string(tex.hsh.terms()) + " terms";
  if (!tex.is_hsh) {
    refuse(input, report.from, "RTI HSH",
           "an HSH basis does not hold a biquadratic polynomial exactly (the conversion is "
           "lossy)");
  }
  const RtiWriteReport r = write_rti(output, tex.hsh);
  char buf[160];
  std::snprintf(buf, sizeof buf, "max coefficient error %.3g, RMS %.3g", r.max_coeff_error,
                r.rms_coeff_error);
  report.quantisation = buf;
  report.file_bytes = r.file_bytes;
  return report;
}

}  // namespace ptmkit::texture
