#include "ptmkit/core/atomic_file.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <mutex>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "ptmkit/core/error.h"

namespace fs = std::filesystem;

namespace ptmkit {

namespace {

std::atomic<unsigned> g_counter{0};

// The open transaction (at most one per process) and what it holds.
struct Pending {
  fs::path temp;
  fs::path target;  // resolved (symbolic links followed)
  fs::path shown;   // as the user gave it
};
struct TransactionState {
  std::mutex mutex;
  bool open = false;
  int immediate = 0;  // Immediate guards alive
  std::vector<Pending> files;
  std::vector<fs::path> created_dirs;
};
TransactionState& state() {
  static TransactionState s;
  return s;
}

std::mutex g_cleaned_mutex;
std::set<fs::path>& cleaned_dirs() {
  static std::set<fs::path> s;
  return s;
}

fs::path folder_of(const fs::path& p) {
  return p.has_parent_path() ? p.parent_path() : fs::path(".");
}

// Eight hex digits naming this machine: a process id means something only on the machine
// that issued it, and several machines may write into one shared folder (an MPI job).
const std::string& host_tag() {
  static const std::string tag = [] {
    char host[256] = {};
    if (::gethostname(host, sizeof host - 1) != 0) host[0] = '\0';
    std::uint32_t h = 2166136261u;  // FNV-1a
    for (const char* c = host; *c != '\0'; ++c) {
      h = (h ^ static_cast<unsigned char>(*c)) * 16777619u;
    }
    char buf[9];
    std::snprintf(buf, sizeof buf, "%08x", h);
    return std::string(buf);
  }();
  return tag;
}

fs::path next_temp(const fs::path& dir, const std::string& ext) {
  std::string name(kTempPrefix);
  name.append(std::to_string(::getpid()))
      .append("-")
      .append(std::to_string(g_counter.fetch_add(1)))
      .append("-")
      .append(host_tag())
      .append(ext);
  return dir / name;
}

// Flushes a finished file to the disk: a delayed write error (a full disk on some file
// systems, an I/O error) surfaces here instead of after the rename.
void sync_file(const fs::path& file, const fs::path& shown) {
  const int fd = ::open(file.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) {
    throw Error(where(shown) + ": cannot reopen the written file: " + std::strerror(errno));
  }
  const int rc = ::fsync(fd);
  const int err = errno;
  ::close(fd);
  // EINVAL: the file system does not sync (a pipe-like or special mount); nothing to flush.
  if (rc != 0 && err != EINVAL) {
    throw Error(where(shown) + ": write failed when flushing to disk: " + std::strerror(err));
  }
}

void sync_folder(const fs::path& dir) {
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return;
  (void)::fsync(fd);  // best effort: the rename itself has happened
  ::close(fd);
}

void rename_into_place(const fs::path& temp, const fs::path& target, const fs::path& shown) {
  if (::rename(temp.c_str(), target.c_str()) != 0) {
    throw Error(where(shown) +
                ": cannot move the finished file into place: " + std::strerror(errno));
  }
}

// A second name for `target`'s current content, so it can be put back. A hard link costs no
// copy; where links are not supported, a copy.
bool keep_copy(const fs::path& target, const fs::path& backup) {
  if (::link(target.c_str(), backup.c_str()) == 0) return true;
  std::error_code ec;
  return fs::copy_file(target, backup, fs::copy_options::overwrite_existing, ec) && !ec;
}

bool process_gone(long pid) {
  if (pid <= 0 || pid == static_cast<long>(::getpid())) return false;
  return ::kill(static_cast<pid_t>(pid), 0) != 0 && errno == ESRCH;
}

// Removes stale temporaries in `dir` the first time this process writes there.
void clean_once(const fs::path& dir) {
  std::error_code ec;
  std::lock_guard<std::mutex> lock(g_cleaned_mutex);
  if (cleaned_dirs().insert(fs::absolute(dir, ec)).second) remove_stale_temporaries(dir);
}

// StagedFolder::commit: `staged` in place of `target` in one step (see atomic_file.h).
void replace_folder(const fs::path& staged, const fs::path& target) {
  std::error_code ec;
  if (!fs::exists(target, ec)) {
    if (::rename(staged.c_str(), target.c_str()) != 0) {
      throw Error(where(target) + ": cannot move the folder into place: " + std::strerror(errno));
    }
    sync_folder(folder_of(target));
    return;
  }
  if (::renameat2(AT_FDCWD, staged.c_str(), AT_FDCWD, target.c_str(), RENAME_EXCHANGE) == 0) {
    sync_folder(folder_of(target));
    fs::remove_all(staged, ec);  // now the earlier folder
    return;
  }
  if (errno != EINVAL && errno != ENOSYS) {
    throw Error(where(target) + ": cannot replace the folder: " + std::strerror(errno));
  }
  // No exchange on this file system: aside, then into place, putting it back on failure.
  const fs::path aside = next_temp(folder_of(target), ".old");
  if (::rename(target.c_str(), aside.c_str()) != 0) {
    throw Error(where(target) + ": cannot replace the folder: " + std::strerror(errno));
  }
  if (::rename(staged.c_str(), target.c_str()) != 0) {
    const int err = errno;
    (void)::rename(aside.c_str(), target.c_str());
    throw Error(where(target) + ": cannot move the folder into place: " + std::strerror(err));
  }
  sync_folder(folder_of(target));
  fs::remove_all(aside, ec);
}

}  // namespace

int remove_stale_temporaries(const fs::path& dir) {
  int removed = 0;
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (name.rfind(kTempPrefix, 0) != 0) continue;
    const std::size_t start = kTempPrefix.size();
    std::size_t stop = start;
    while (stop < name.size() && name[stop] >= '0' && name[stop] <= '9') ++stop;
    if (stop == start || stop - start > 9 || stop >= name.size() || name[stop] != '-') continue;
    // PID-N-HOST: only this machine can tell whether the process is gone.
    std::size_t n_end = stop + 1;
    while (n_end < name.size() && name[n_end] >= '0' && name[n_end] <= '9') ++n_end;
    if (n_end + 9 <= name.size() && name[n_end] == '-' &&
        name.find_first_not_of("0123456789abcdef", n_end + 1) >= n_end + 9 &&
        name.compare(n_end + 1, 8, host_tag()) != 0) {
      continue;
    }
    if (!process_gone(std::stol(name.substr(start, stop - start)))) continue;
    std::error_code ec2;
    if (it->is_symlink(ec2)) continue;
    if (it->is_regular_file(ec2) && fs::remove(it->path(), ec2)) {
      ++removed;
    } else if (it->is_directory(ec2) && fs::remove_all(it->path(), ec2) > 0 && !ec2) {
      ++removed;  // a folder of outputs a killed run was staging
    }
  }
  return removed;
}

fs::path temporary_path(const fs::path& dir, std::string_view suffix) {
  clean_once(dir);
  return next_temp(dir, std::string(suffix));
}

StagedFolder::StagedFolder(fs::path target, std::string_view suffix) : target_(std::move(target)) {
  if (target_.filename().empty()) target_ = target_.parent_path();  // "out/" names "out"
  const fs::path dir = folder_of(target_);
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw Error(where(dir) + ": no such folder");
  path_ = temporary_path(dir, suffix);
  if (!fs::create_directory(path_, ec)) {
    const fs::path p = std::exchange(path_, fs::path());
    throw Error(where(p) + ": cannot create a temporary folder: " + ec.message());
  }
}

StagedFolder::~StagedFolder() {
  if (!path_.empty()) {
    std::error_code ec;
    fs::remove_all(path_, ec);
  }
}

void StagedFolder::commit() {
  replace_folder(path_, target_);
  path_.clear();
}

AtomicOutput::AtomicOutput(fs::path target) : target_(std::move(target)) {
  if (target_.empty()) throw Error("output path is empty");
  resolved_ = target_;
  struct stat st {};
  if (::lstat(target_.c_str(), &st) == 0 && S_ISLNK(st.st_mode)) {
    // Written through: the file the link names is replaced, the link stays.
    std::error_code ec;
    resolved_ = fs::canonical(target_, ec);
    if (ec) {
      throw Error(where(target_) +
                  ": is a symbolic link to a missing file or folder; not writing through it");
    }
  }
  if (::lstat(resolved_.c_str(), &st) == 0) {
    if (S_ISDIR(st.st_mode)) throw Error(where(target_) + ": is a folder, expected a file name");
    if (!S_ISREG(st.st_mode)) {
      throw Error(where(target_) +
                  ": is not a regular file (a device, FIFO or socket); refusing to replace it");
    }
  }
  const fs::path dir = folder_of(resolved_);
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) {
    throw Error(where(target_) + ": the folder " + dir.string() + " does not exist");
  }
  clean_once(dir);
  temp_ = next_temp(dir, resolved_.extension().string());
}

AtomicOutput::~AtomicOutput() {
  if (!committed_) {
    std::error_code ec;
    fs::remove(temp_, ec);
  }
}

void AtomicOutput::commit() {
  struct stat st {};
  if (::lstat(temp_.c_str(), &st) != 0 || !S_ISREG(st.st_mode)) {
    throw Error(where(target_) + ": nothing was written");
  }
  sync_file(temp_, target_);
  TransactionState& s = state();
  {
    std::lock_guard<std::mutex> lock(s.mutex);
    if (s.open && s.immediate == 0) {
      s.files.push_back({temp_, resolved_, target_});
      committed_ = true;  // the transaction owns the temporary now
      return;
    }
  }
  rename_into_place(temp_, resolved_, target_);
  committed_ = true;
  sync_folder(folder_of(resolved_));
}

OutputTransaction::OutputTransaction() {
  TransactionState& s = state();
  std::lock_guard<std::mutex> lock(s.mutex);
  if (s.open) return;  // joins the open one
  s.open = true;
  s.files.clear();
  s.created_dirs.clear();
  outermost_ = true;
}

std::size_t OutputTransaction::queued() const {
  if (!outermost_) return 0;
  TransactionState& s = state();
  std::lock_guard<std::mutex> lock(s.mutex);
  return s.files.size();
}

OutputTransaction::~OutputTransaction() {
  if (!outermost_ || done_) return;
  TransactionState& s = state();
  std::lock_guard<std::mutex> lock(s.mutex);
  std::error_code ec;
  for (const Pending& p : s.files) fs::remove(p.temp, ec);
  for (auto it = s.created_dirs.rbegin(); it != s.created_dirs.rend(); ++it) {
    fs::remove(*it, ec);  // only if empty
  }
  s.files.clear();
  s.created_dirs.clear();
  s.open = false;
}

void OutputTransaction::commit() {
  if (!outermost_ || done_) return;
  TransactionState& s = state();
  std::vector<Pending> files;
  std::vector<fs::path> created;
  {
    std::lock_guard<std::mutex> lock(s.mutex);
    files.swap(s.files);
    created.swap(s.created_dirs);
    s.open = false;
  }
  done_ = true;
  // Each target's earlier content, kept under a temporary name until every file is in place.
  struct Replaced {
    fs::path target;
    fs::path backup;  // empty: the target did not exist
  };
  std::vector<Replaced> replaced;
  std::error_code ec;
  std::size_t i = 0;
  try {
    for (; i < files.size(); ++i) {
      const Pending& p = files[i];
      Replaced r{p.target, {}};
      struct stat st {};
      if (::lstat(p.target.c_str(), &st) == 0) {
        if (!S_ISREG(st.st_mode)) {
          throw Error(where(p.shown) + ": is no longer a regular file; refusing to replace it");
        }
        r.backup = next_temp(folder_of(p.target), "");
        if (!keep_copy(p.target, r.backup)) {
          throw Error(where(p.shown) + ": cannot keep the earlier file while replacing it");
        }
      }
      try {
        rename_into_place(p.temp, p.target, p.shown);
      } catch (...) {
        if (!r.backup.empty()) fs::remove(r.backup, ec);
        throw;
      }
      replaced.push_back(r);
    }
  } catch (...) {
    // Put back what was replaced, remove what was new, drop the rest.
    for (auto it = replaced.rbegin(); it != replaced.rend(); ++it) {
      if (it->backup.empty()) {
        fs::remove(it->target, ec);
      } else {
        (void)::rename(it->backup.c_str(), it->target.c_str());
      }
    }
    for (std::size_t k = i; k < files.size(); ++k) fs::remove(files[k].temp, ec);
    for (auto it = created.rbegin(); it != created.rend(); ++it) fs::remove(*it, ec);
    throw;
  }
  std::set<fs::path> dirs;
  for (const Replaced& r : replaced) {
    if (!r.backup.empty()) fs::remove(r.backup, ec);
    dirs.insert(folder_of(r.target));
  }
  for (const fs::path& d : dirs) sync_folder(d);
}

OutputTransaction::Immediate::Immediate() {
  TransactionState& s = state();
  std::lock_guard<std::mutex> lock(s.mutex);
  ++s.immediate;
}

OutputTransaction::Immediate::~Immediate() {
  TransactionState& s = state();
  std::lock_guard<std::mutex> lock(s.mutex);
  --s.immediate;
}

void write_file_atomic(const fs::path& path, std::string_view contents) {
  AtomicOutput out(path);
  FILE* f = std::fopen(out.temp_path().c_str(), "wb");
  if (f == nullptr) {
    throw Error(where(path) + ": cannot open for writing: " + std::strerror(errno));
  }
  const std::size_t n = std::fwrite(contents.data(), 1, contents.size(), f);
  const int write_errno = errno;
  const bool flushed = std::fflush(f) == 0;
  const int flush_errno = errno;
  const bool closed = std::fclose(f) == 0;
  if (n != contents.size() || !flushed || !closed) {
    const int err = n != contents.size() ? write_errno : !flushed ? flush_errno : errno;
    throw Error(where(path) + ": write failed: " + std::strerror(err));
  }
  out.commit();
}

void ensure_directory(const fs::path& dir) {
  std::error_code ec;
  // The folders that do not exist yet, outermost first: a failed transaction removes them.
  std::vector<fs::path> missing;
  for (fs::path p = dir; !p.empty() && !fs::exists(p, ec); p = p.parent_path()) {
    missing.insert(missing.begin(), p);
    if (p == p.parent_path()) break;
  }
  fs::create_directories(dir, ec);
  if (ec || !fs::is_directory(dir)) {
    throw Error(where(dir) + ": cannot create folder" + (ec ? ": " + ec.message() : ""));
  }
  TransactionState& s = state();
  std::lock_guard<std::mutex> lock(s.mutex);
  if (s.open) s.created_dirs.insert(s.created_dirs.end(), missing.begin(), missing.end());
}

}  // namespace ptmkit
