// What ptmkit reads, in one place, and the one wording every refusal of an unsupported
// variant uses (a .ptm format, an .rti type, a web folder's type, colour space or layout), so
// that a user who meets one refusal learns everything that would have been accepted.
// docs/FORMATS.md has the full table, with the test that shows each row.
#pragma once

#include <string>
#include <string_view>

namespace ptmkit::texture {

// The readable variants, as a sentence fragment.
inline constexpr std::string_view kSupportedFormats =
    "supported: .ptm PTM_1.2 PTM_FORMAT_RGB, PTM_FORMAT_LRGB, PTM_FORMAT_JPEG_RGB, "
    "PTM_FORMAT_JPEG_LRGB, PTM_FORMAT_LUM (and PTM_1.1 PTM_FORMAT_LRGB); .rti RTI type 3 (HSH, 4, "
    "9 or 16 "
    "terms); relight/OpenLIME web folders (info.json) of type ptm or hsh, colour space rgb or "
    "lrgb, layout image or deepzoom";

// "<variant> is not supported (supported: ...)". `variant` names the format as the file
// spells it, e.g. "PTM_FORMAT_PTM_LUT" or "web folder type 'rbf'".
[[nodiscard]] inline std::string unsupported_variant(std::string_view variant) {
  std::string s(variant);
  s += " is not supported (";
  s += kSupportedFormats;
  s += ")";
  return s;
}

}  // namespace ptmkit::texture
