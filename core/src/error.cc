#include "ptmkit/core/error.h"

#include <cstdio>

namespace ptmkit {

namespace {

// Length of a valid UTF-8 sequence starting at text[i] (2..4), or 0.
std::size_t utf8_length(std::string_view text, std::size_t i) {
  const auto c = static_cast<unsigned char>(text[i]);
  const std::size_t n = c >= 0xF0 && c < 0xF5 ? 4 : c >= 0xE0 ? 3 : c >= 0xC2 && c < 0xE0 ? 2 : 0;
  if (n == 0 || (c >= 0xE0 && n == 2) || i + n > text.size()) return 0;
  for (std::size_t k = 1; k < n; ++k) {
    if ((static_cast<unsigned char>(text[i + k]) & 0xC0) != 0x80) return 0;
  }
  return n;
}

// Printable ASCII and valid UTF-8 (non-ASCII names) pass; every other byte becomes \xNN.
void append_printable(std::string_view text, std::string* out) {
  for (std::size_t i = 0; i < text.size(); ++i) {
    const auto c = static_cast<unsigned char>(text[i]);
    if (c >= 0x20 && c < 0x7f) {
      out->push_back(text[i]);
      continue;
    }
    if (const std::size_t n = c >= 0x80 ? utf8_length(text, i) : 0; n > 0) {
      out->append(text.substr(i, n));
      i += n - 1;
      continue;
    }
    char hex[8];
    std::snprintf(hex, sizeof(hex), "\\x%02X", static_cast<unsigned>(c));
    out->append(hex);
  }
}

}  // namespace

std::string excerpt(std::string_view text) {
  std::string out;
  if (text.size() <= kMaxExcerptBytes) {
    append_printable(text, &out);
    return out;
  }
  const std::size_t keep = kMaxExcerptBytes / 2;
  append_printable(text.substr(0, keep), &out);
  out += "...(" + std::to_string(text.size()) + " bytes)...";
  append_printable(text.substr(text.size() - keep), &out);
  return out;
}

std::string where(const std::filesystem::path& file, int line) {
  std::string s = excerpt(file.native());
  if (line <= 0) return s;
  char suffix[24];
  std::snprintf(suffix, sizeof(suffix), ":%d", line);
  return s.append(suffix);
}

}  // namespace ptmkit
