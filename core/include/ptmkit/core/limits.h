// Input limits: every reader checks what a file declares against these named maxima, against
// the file's actual size and against the memory available, before it allocates anything.
// docs/RELIABILITY.md lists them with the tests that check each.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>

#include "ptmkit/core/error.h"  // excerpt()

namespace ptmkit {

// Text inputs read whole (.lp light files, JSON: boards, domes, cameras, planes, lights).
inline constexpr std::uintmax_t kMaxTextFileBytes = std::uintmax_t{64} << 20;  // 64 MiB
// Lights in one light set: a .lp file, a dome JSON, a ring layout.
inline constexpr long long kMaxLights = 10000;
// Lights in one ring of a ring layout (elevation:count).
inline constexpr long long kMaxRingLights = 10000;
// Tags on one calibration board (a grid's cols x rows, or a tag list).
inline constexpr long long kMaxBoardTags = 100000;
// Largest tag id a board may name (ids are ints; a grid's last id is first_id + tags - 1).
inline constexpr long long kMaxTagId = (1LL << 31) - 1;
// Characters of a file name read from an input (Linux's PATH_MAX).
inline constexpr std::size_t kMaxPathChars = 4096;

// Largest coefficient magnitude a texture writer accepts (.ptm, .rti): the largest half float.
// Intensities are normalised to full scale 1; a coefficient beyond this comes from a
// degenerate fit or absurd input (floats near 3e38) and would relight to garbage.
inline constexpr double kMaxCoefficient = 65504.0;

// Throws ptmkit::Error naming `path` and the first texel (x, y) holding a value that is not
// finite or whose magnitude exceeds kMaxCoefficient. `values` holds `per_texel` values per
// texel, texels in rows of `width`, the first in row `first_row`.
void check_coefficients(const std::filesystem::path& path, const float* values, std::size_t count,
                        int width, int per_texel, int first_row = 0);

// The file's size in bytes, checked: it must be a regular file (not a device, FIFO or folder:
// `/dev/zero` is refused before a byte is read) of at most `max_bytes`. `kind` names it in
// the error ("light file").
std::uintmax_t checked_input_size(const std::filesystem::path& path, std::uintmax_t max_bytes,
                                  std::string_view kind);

// Memory this process may still allocate, in bytes: MemAvailable plus free swap (from
// /proc/meminfo), else the physical memory size; capped by RLIMIT_AS where one is set, by
// what a cgroup v2 memory limit leaves (a batch scheduler's job limit, a container's), and by
// set_memory_budget_bytes().
std::uint64_t available_memory_bytes();

// Caps available_memory_bytes() for this process at `bytes` (0: no cap, the default), for an
// application embedding ptmkit that keeps its own budget. Thread-safe.
void set_memory_budget_bytes(std::uint64_t bytes);

// Throws ptmkit::Error naming `path` when allocating `bytes` for `what` (e.g. "the 4096 x
// 4096 x 16-term coefficients") would exceed available_memory_bytes().
void check_allocation(const std::filesystem::path& path, std::uint64_t bytes,
                      std::string_view what);

// `a * b` for sizes read from files; throws ptmkit::Error naming `path` on overflow.
std::uint64_t checked_multiply(const std::filesystem::path& path, std::uint64_t a, std::uint64_t b);

}  // namespace ptmkit
