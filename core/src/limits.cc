#include "ptmkit/core/limits.h"

#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <limits>

#include "ptmkit/core/error.h"

namespace fs = std::filesystem;

namespace ptmkit {

namespace {

std::string mib(std::uint64_t bytes) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.1f MiB", static_cast<double>(bytes) / 1048576.0);
  return buf;
}

}  // namespace

std::uintmax_t checked_input_size(const fs::path& path, std::uintmax_t max_bytes,
                                  std::string_view kind) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) {
    throw Error(where(path) + ": cannot open the " + std::string(kind) + ": " +
                std::strerror(errno));
  }
  if (S_ISDIR(st.st_mode)) {
    throw Error(where(path) + ": is a folder, expected a " + std::string(kind));
  }
  if (!S_ISREG(st.st_mode)) {
    throw Error(where(path) + ": is not a regular file (a device, FIFO or socket); expected a " +
                std::string(kind));
  }
  const auto size = static_cast<std::uintmax_t>(st.st_size);
  if (size > max_bytes) {
    throw Error(where(path) + ": " + mib(size) + ", more than a " + std::string(kind) +
                " may be (at most " + mib(max_bytes) + ")");
  }
  return size;
}

namespace {

std::atomic<std::uint64_t> g_budget_bytes{0};

// What a cgroup v2 memory limit leaves: the smallest memory.max - memory.current over the
// process's cgroup and its ancestors (a batch scheduler's job limit may sit on either).
std::uint64_t cgroup_room_bytes() {
  std::ifstream self("/proc/self/cgroup");
  std::string line;
  std::string rel;
  while (std::getline(self, line)) {
    if (line.rfind("0::", 0) == 0) rel = line.substr(3);
  }
  std::uint64_t room = std::numeric_limits<std::uint64_t>::max();
  if (rel.empty()) return room;
  fs::path dir = fs::path("/sys/fs/cgroup") / fs::path(rel).relative_path();
  for (int depth = 0; depth < 64; ++depth) {
    std::ifstream max_file(dir / "memory.max");
    std::ifstream current_file(dir / "memory.current");
    std::string max_text;
    std::uint64_t current = 0;
    if (max_file >> max_text && max_text != "max" && current_file >> current) {
      char* end = nullptr;
      const unsigned long long limit = std::strtoull(max_text.c_str(), &end, 10);
      if (end != max_text.c_str() && *end == '\0') {
        room = std::min<std::uint64_t>(room, limit > current ? limit - current : 0);
      }
    }
    if (dir == "/sys/fs/cgroup" || !dir.has_parent_path() || dir.parent_path() == dir) break;
    dir = dir.parent_path();
  }
  return room;
}

}  // namespace

void set_memory_budget_bytes(std::uint64_t bytes) { g_budget_bytes.store(bytes); }

std::uint64_t available_memory_bytes() {
  std::uint64_t available = 0;
  std::ifstream meminfo("/proc/meminfo");
  std::string key;
  std::uint64_t kib = 0;
  std::string unit;
  bool found = false;
  while (meminfo >> key >> kib) {
    std::getline(meminfo, unit);
    if (key == "MemAvailable:" || key == "SwapFree:") {
      available += kib * 1024;
      found = found || key == "MemAvailable:";
    }
  }
  if (!found) {
    const long pages = ::sysconf(_SC_PHYS_PAGES);
    const long page = ::sysconf(_SC_PAGESIZE);
    available = pages > 0 && page > 0
                    ? static_cast<std::uint64_t>(pages) * static_cast<std::uint64_t>(page)
                    : std::numeric_limits<std::uint64_t>::max();
  }
  struct rlimit rl {};
  if (::getrlimit(RLIMIT_AS, &rl) == 0 && rl.rlim_cur != RLIM_INFINITY) {
    available = std::min<std::uint64_t>(available, rl.rlim_cur);
  }
  available = std::min(available, cgroup_room_bytes());
  const std::uint64_t budget = g_budget_bytes.load();
  if (budget != 0) available = std::min(available, budget);
  return available;
}

void check_allocation(const fs::path& path, std::uint64_t bytes, std::string_view what) {
  const std::uint64_t available = available_memory_bytes();
  if (bytes > available) {
    throw Error(where(path) + ": " + std::string(what) + " need " + mib(bytes) +
                ", more than the memory available (" + mib(available) + ")");
  }
}

std::uint64_t checked_multiply(const fs::path& path, std::uint64_t a, std::uint64_t b) {
  if (a != 0 && b > std::numeric_limits<std::uint64_t>::max() / a) {
    throw Error(where(path) + ": declared sizes overflow (" + std::to_string(a) + " x " +
                std::to_string(b) + ")");
  }
  return a * b;
}

void check_coefficients(const fs::path& path, const float* values, std::size_t count, int width,
                        int per_texel, int first_row) {
  for (std::size_t i = 0; i < count; ++i) {
    const float v = values[i];
    if (std::isfinite(v) && std::abs(v) <= kMaxCoefficient) continue;
    const std::size_t texel = i / static_cast<std::size_t>(per_texel);
    const std::size_t x = texel % static_cast<std::size_t>(width);
    const std::size_t y =
        texel / static_cast<std::size_t>(width) + static_cast<std::size_t>(first_row);
    char buf[200];
    std::snprintf(buf, sizeof buf,
                  ": coefficient %zu of texel (%zu, %zu) is %g: %s; nothing was written",
                  i % static_cast<std::size_t>(per_texel), x, y, static_cast<double>(v),
                  std::isfinite(v) ? "beyond what the format represents (at most 65504 in "
                                     "magnitude)"
                                   : "not a finite number");
    throw Error(where(path) + buf);
  }
}

}  // namespace ptmkit
