// Errors that a user can cause (bad files, bad options) and how they are reported.
//
// Library functions throw ptmkit::Error for user errors. The message is meant for the user:
// it names the file (and line, where there is one) and says what is wrong. Programmer errors
// (violated preconditions inside the library) are assert()ed, not thrown.
#pragma once

#include <filesystem>
#include <stdexcept>
#include <string>

namespace ptmkit {

class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// "FILE: message" or "FILE:LINE: message" (line is 1-based; 0 means no line).
[[nodiscard]] std::string where(const std::filesystem::path& file, int line = 0);

}  // namespace ptmkit
