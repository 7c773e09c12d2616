#include "ptmkit/core/error.h"

#include <cstdio>

namespace ptmkit {

std::string where(const std::filesystem::path& file, int line) {
  std::string s = file.string();
  if (line <= 0) return s;
  char suffix[24];
  std::snprintf(suffix, sizeof(suffix), ":%d", line);
  return s.append(suffix);
}

}  // namespace ptmkit
