#include "ptmkit/core/raw_file.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdint>
#include <cstring>
#include <new>
#include <string>

#include "ptmkit/core/error.h"

namespace ptmkit {

namespace {

// The whole pages inside the bytes [begin, end) (addresses or file offsets): [lo, hi), none
// when hi <= lo.
struct PageSpan {
  std::uintptr_t lo = 0, hi = 0;
};
PageSpan whole_pages(std::uintptr_t begin, std::uintptr_t end) {
  const auto page = static_cast<std::uintptr_t>(::sysconf(_SC_PAGESIZE));
  return {(begin + page - 1) / page * page, end / page * page};
}

}  // namespace

RawFile::~RawFile() {
  if (fd_ >= 0) ::close(fd_);
}

RawFile RawFile::create(const std::filesystem::path& path, const std::filesystem::path& what) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) throw Error(where(what) + ": cannot open for writing");
  return RawFile(fd);
}

RawFile RawFile::open_for_writing(const std::filesystem::path& path,
                                  const std::filesystem::path& what) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CLOEXEC);
  if (fd < 0) {
    throw Error(where(what) + ": cannot open " + excerpt(path.filename().string()) +
                " for writing: " + std::strerror(errno));
  }
  return RawFile(fd);
}

RawFile RawFile::create_unlinked(const std::filesystem::path& path) {
  const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_EXCL | O_CLOEXEC, 0600);
  if (fd < 0) {
    throw Error(where(path) +
                ": cannot create the temporary coefficient file: " + std::strerror(errno));
  }
  ::unlink(path.c_str());
  return RawFile(fd);
}

void RawFile::write_at(const void* data, std::size_t bytes, std::size_t offset,
                       const std::filesystem::path& what) const {
  const auto* p = static_cast<const char*>(data);
  while (bytes > 0) {
    const ssize_t n = ::pwrite(fd_, p, bytes, static_cast<off_t>(offset));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) throw Error(where(what) + ": write failed: " + std::strerror(errno));
    p += n;
    bytes -= static_cast<std::size_t>(n);
    offset += static_cast<std::size_t>(n);
  }
}

void RawFile::start_writeback(std::size_t offset, std::size_t bytes) const {
  (void)::sync_file_range(fd_, static_cast<off_t>(offset), static_cast<off_t>(bytes),
                          SYNC_FILE_RANGE_WRITE);
}

void RawFile::read_at(void* data, std::size_t bytes, std::size_t offset,
                      const std::filesystem::path& what) const {
  auto* p = static_cast<char*>(data);
  while (bytes > 0) {
    const ssize_t n = ::pread(fd_, p, bytes, static_cast<off_t>(offset));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) throw Error(where(what) + ": cannot read back the temporary coefficients");
    p += n;
    bytes -= static_cast<std::size_t>(n);
    offset += static_cast<std::size_t>(n);
  }
}

void RawFile::punch_hole(std::size_t offset, std::size_t bytes) const {
  const PageSpan p = whole_pages(offset, offset + bytes);
  if (p.hi > p.lo) {
    (void)::fallocate(fd_, FALLOC_FL_PUNCH_HOLE | FALLOC_FL_KEEP_SIZE, static_cast<off_t>(p.lo),
                      static_cast<off_t>(p.hi - p.lo));
  }
}

void RawFile::close(const std::filesystem::path& what) {
  const int fd = std::exchange(fd_, -1);
  if (fd >= 0 && ::close(fd) != 0) {
    throw Error(where(what) + ": write failed: " + std::strerror(errno));
  }
}

void drop_cached_pages(const std::filesystem::path& path) {
  // O_NONBLOCK keeps a FIFO's open from waiting for a writer.
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NOFOLLOW | O_NONBLOCK);
  if (fd < 0) return;
  struct stat st {};
  if (::fstat(fd, &st) == 0 && S_ISREG(st.st_mode)) {
    (void)::posix_fadvise(fd, 0, 0, POSIX_FADV_DONTNEED);
  }
  ::close(fd);
}

void PageMemory::allocate(std::size_t bytes) {
  release();
  if (bytes == 0) return;
  void* p = ::mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  if (p == MAP_FAILED) throw std::bad_alloc();
  data_ = p;
  bytes_ = bytes;
}

void PageMemory::discard(std::size_t offset, std::size_t bytes) {
  if (data_ == nullptr || bytes == 0) return;
  const auto base = reinterpret_cast<std::uintptr_t>(data_);
  const PageSpan p = whole_pages(base + offset, base + offset + bytes);
  if (p.hi > p.lo) ::madvise(reinterpret_cast<void*>(p.lo), p.hi - p.lo, MADV_DONTNEED);
}

void PageMemory::release() {
  if (data_ != nullptr) ::munmap(data_, bytes_);
  data_ = nullptr;
  bytes_ = 0;
}

RawFile open_shared_output(Collective* peers, const std::filesystem::path& target,
                           std::string_view head, std::optional<AtomicOutput>* out) {
  RawFile file;
  std::string temp;
  if (peers == nullptr || peers->rank() == 0) {
    try {
      out->emplace(target);
      temp = (*out)->temp_path().string();
      file = RawFile::create(temp, target);
      file.write_at(head.data(), head.size(), 0, target);
    } catch (const Error&) {
      // The others stop at the agreement below; this process's own error is the message.
      if (peers != nullptr) (void)peers->all(false);
      throw;
    }
  }
  if (peers != nullptr) {
    peers->agree(true, where(target));
    peers->broadcast(&temp);
    if (peers->rank() != 0) file = RawFile::open_for_writing(temp, target);
  }
  return file;
}

}  // namespace ptmkit
