// Shared by the libFuzzer targets: the readers take paths, so each input is written to a file
// of this process first. A reader may reject an input only with ptmkit::Error: any other
// exception escapes, and libFuzzer reports it (as it does crashes, leaks, sanitizer reports,
// timeouts and allocations past -rss_limit_mb / -malloc_limit_mb).
#pragma once

#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <string>

#include "ptmkit/core/error.h"
#include "ptmkit/core/limits.h"

namespace ptmkit::fuzz {

// The readers check their allocations against the memory available; under the fuzzer that is
// half its -malloc_limit_mb (scripts/fuzz.sh), so an allocation a reader checked is never a
// finding and one it did not check still is.
inline const bool kMemoryBudgetSet =
    (ptmkit::set_memory_budget_bytes(std::uint64_t{1} << 30), true);

inline std::filesystem::path input_file(const std::uint8_t* data, std::size_t size,
                                        const std::string& name) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("ptmkit-fuzz-" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const std::filesystem::path path = dir / name;
  FILE* f = std::fopen(path.c_str(), "wb");
  if (f == nullptr) std::abort();
  if (size > 0 && std::fwrite(data, 1, size, f) != size) std::abort();
  std::fclose(f);
  return path;
}

template <class Read>
void expect_value_or_error(Read read) {
  try {
    read();
  } catch (const ptmkit::Error&) {
  }
}

}  // namespace ptmkit::fuzz
