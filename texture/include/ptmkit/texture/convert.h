// Conversions between the texture formats ptmkit reads and writes (`ptmkit export ptm|rti`),
// in every direction that loses nothing the target can hold; the others are refused with the
// reason (docs/FORMATS.md has the table).
//
// To .ptm (target format: the source's own, or rgb, lrgb, jpeg-rgb, jpeg-lrgb):
//   .ptm of the same colour model: the stored bytes, scales and biases are kept (PTM_1.1 is
//     re-laid out as 1.2); raw targets are therefore bit-exact copies of what was stored (a
//     JPEG source's decoded bytes), JPEG targets lose what JPEG at `jpeg_quality` loses.
//   .ptm LRGB -> RGB: each channel's polynomial is luminance x colour, re-quantised.
//   web folder ptm rgb -> RGB, lrgb -> LRGB (or RGB): quantised to the .ptm's bytes.
//   RGB -> LRGB: refused (one luminance polynomial cannot hold three independent ones).
//   HSH (.rti, web hsh) -> .ptm: refused (the six-term polynomial cannot hold an HSH basis).
// To .rti:
//   .rti: re-quantised (per-term range) and written with CRLF header lines.
//   web folder hsh: quantised to the .rti's bytes.
//   .ptm and web ptm -> .rti: refused (an HSH basis does not hold a biquadratic exactly).
#pragma once

#include <cstddef>
#include <filesystem>
#include <string>

#include "ptmkit/core/image.h"
#include "ptmkit/texture/ptm.h"

namespace ptmkit::texture {

struct ConvertOptions {
  // .ptm target: "" (the source's own format: its colour model, and JPEG when the source is a
  // JPEG .ptm), "rgb", "lrgb", "jpeg-rgb", "jpeg-lrgb".
  std::string ptm_format;
  // JPEG quality (1..100) of JPEG .ptm targets; 0: the source's own when it is a JPEG .ptm,
  // else 90.
  int jpeg_quality = 0;
  // Options of any re-quantisation (its error report; integer_scales re-quantises even a
  // same-format .ptm, with whole-number scales for readers that truncate, docs/FORMATS.md).
  PtmWriteOptions write;
};

struct ConvertReport {
  std::filesystem::path input, output;
  std::string from, to;      // format names, e.g. "PTM_FORMAT_JPEG_LRGB" -> "PTM_FORMAT_LRGB"
  bool bytes_kept = false;   // the source's coefficient bytes, scales and biases were kept
  std::string quantisation;  // what re-quantising cost, when it happened
  std::size_t file_bytes = 0;
};

// Reads `input` (.ptm, .rti or web folder) and writes `output` atomically. Errors: the
// readers', an unknown ptm_format, a refused direction (message with the reason).
ConvertReport convert_to_ptm(const std::filesystem::path& input,
                             const std::filesystem::path& output, const ConvertOptions& options);
ConvertReport convert_to_rti(const std::filesystem::path& input,
                             const std::filesystem::path& output, const ConvertOptions& options);

}  // namespace ptmkit::texture
