// Errors that a user can cause (bad files, bad options) and how they are reported.
//
// Library functions throw ptmkit::Error for user errors. The message is meant for the user:
// it names the file (and line, where there is one) and says what is wrong. Programmer errors
// (violated preconditions inside the library) are assert()ed, not thrown.
#pragma once

#include <filesystem>
#include <stdexcept>
#include <string>
#include <string_view>

namespace ptmkit {

class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// "FILE: message" or "FILE:LINE: message" (line is 1-based; 0 means no line). The file name
// goes through excerpt(): a name of megabytes or with control bytes is never echoed whole.
[[nodiscard]] std::string where(const std::filesystem::path& file, int line = 0);

// Longest excerpt of an input that a message quotes, in bytes.
inline constexpr std::size_t kMaxExcerptBytes = 120;

// A short, printable excerpt of untrusted text or bytes for an error message: bytes outside
// printable ASCII become \xNN, and past kMaxExcerptBytes the middle is replaced by
// "...(N bytes)..." keeping the start and the end (where a file name's distinguishing part is).
[[nodiscard]] std::string excerpt(std::string_view text);

}  // namespace ptmkit
