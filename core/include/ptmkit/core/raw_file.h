// Low-level file and memory plumbing for large outputs (the .ptm stream writer): a file with
// positioned reads and writes, hole punching and cache dropping, and page-granular anonymous
// memory that can be given back piece by piece. POSIX (Linux) underneath; this header is the
// whole interface, so another platform needs only core/src/raw_file.cc.
#pragma once

#include <cstddef>
#include <filesystem>
#include <optional>
#include <string_view>
#include <utility>

#include "ptmkit/core/atomic_file.h"
#include "ptmkit/core/collective.h"

namespace ptmkit {

// An open file, closed on destruction; move-only.
class RawFile {
 public:
  RawFile() = default;
  RawFile(const RawFile&) = delete;
  RawFile& operator=(const RawFile&) = delete;
  RawFile(RawFile&& o) noexcept : fd_(std::exchange(o.fd_, -1)) {}
  RawFile& operator=(RawFile&& o) noexcept {
    std::swap(fd_, o.fd_);
    return *this;
  }
  ~RawFile();

  // For writing, created or truncated. Throws ptmkit::Error naming `what` (the file `path`
  // stands for, e.g. the target of a temporary).
  [[nodiscard]] static RawFile create(const std::filesystem::path& path,
                                      const std::filesystem::path& what);
  // An existing file, for writing in place (another process created it; a distributed
  // writer's share of one output). Throws ptmkit::Error naming `what`.
  [[nodiscard]] static RawFile open_for_writing(const std::filesystem::path& path,
                                                const std::filesystem::path& what);
  // A new file for reading and writing that no other process may have opened, removed from
  // its folder at once: nothing is left behind whatever happens to the process. Throws
  // ptmkit::Error naming the path.
  [[nodiscard]] static RawFile create_unlinked(const std::filesystem::path& path);

  [[nodiscard]] bool is_open() const { return fd_ >= 0; }
  // All `bytes` at `offset`; throws ptmkit::Error naming `what` on failure.
  void write_at(const void* data, std::size_t bytes, std::size_t offset,
                const std::filesystem::path& what) const;
  void read_at(void* data, std::size_t bytes, std::size_t offset,
               const std::filesystem::path& what) const;
  // Frees the whole pages of bytes [offset, offset + bytes) that are no longer needed. Only an
  // economy: a file system without hole punching keeps them until the file is closed.
  void punch_hole(std::size_t offset, std::size_t bytes) const;
  // Starts writing bytes [offset, offset + bytes) back to the disk without waiting, so that
  // the flush before a commit finds little left to do. Only an economy: nothing is reported.
  void start_writeback(std::size_t offset, std::size_t bytes) const;
  // Closes, reporting a failed close (a write the kernel could not finish) as ptmkit::Error
  // naming `what`.
  void close(const std::filesystem::path& what);

 private:
  explicit RawFile(int fd) : fd_(fd) {}
  int fd_ = -1;
};

// Drops the clean cached pages of the regular file at `path` (its contents are untouched);
// anything else at the path (nothing, a symbolic link, a FIFO, a device) is left alone.
void drop_cached_pages(const std::filesystem::path& path);

// The output file of a write shared by the processes of a job (core/collective.h; `peers`
// nullptr: one process). Rank 0 creates `target`'s temporary into *out and writes `head` at
// offset 0; after an agreement (rank 0's failure to create it stops every process, its own
// error propagating) the others open the same temporary. Returns this process's handle for
// positioned writes; rank 0 commits *out after its own agreement that every part is written.
[[nodiscard]] RawFile open_shared_output(Collective* peers, const std::filesystem::path& target,
                                         std::string_view head, std::optional<AtomicOutput>* out);

// Anonymous memory in whole pages: the kernel's zero pages, first touched by whoever fills
// them; parts can be given back once no longer needed.
class PageMemory {
 public:
  PageMemory() = default;
  PageMemory(const PageMemory&) = delete;
  PageMemory& operator=(const PageMemory&) = delete;
  PageMemory(PageMemory&& o) noexcept
      : data_(std::exchange(o.data_, nullptr)), bytes_(std::exchange(o.bytes_, 0)) {}
  PageMemory& operator=(PageMemory&& o) noexcept {
    std::swap(data_, o.data_);
    std::swap(bytes_, o.bytes_);
    return *this;
  }
  ~PageMemory() { release(); }

  // `bytes` zeroed bytes; throws std::bad_alloc when the memory is not there.
  void allocate(std::size_t bytes);
  // Gives back the whole pages inside bytes [offset, offset + bytes) (they read as zero
  // afterwards); pages shared with the bytes either side stay.
  void discard(std::size_t offset, std::size_t bytes);
  [[nodiscard]] void* data() const { return data_; }
  [[nodiscard]] std::size_t bytes() const { return bytes_; }

 private:
  void release();
  void* data_ = nullptr;
  std::size_t bytes_ = 0;
};

// PageMemory as an array of T (trivially copyable).
template <class T>
class LargeBuffer {
 public:
  void allocate(std::size_t n) {
    mem_.allocate(n * sizeof(T));
    size_ = n;
  }
  void discard(std::size_t first, std::size_t n) { mem_.discard(first * sizeof(T), n * sizeof(T)); }
  [[nodiscard]] T* data() { return static_cast<T*>(mem_.data()); }
  [[nodiscard]] const T* data() const { return static_cast<const T*>(mem_.data()); }
  [[nodiscard]] std::size_t size() const { return size_; }
  T& operator[](std::size_t k) { return data()[k]; }
  const T& operator[](std::size_t k) const { return data()[k]; }

 private:
  PageMemory mem_;
  std::size_t size_ = 0;
};

}  // namespace ptmkit
