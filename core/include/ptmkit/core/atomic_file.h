// Output commit: every file ptmkit writes goes through AtomicOutput, so that an output path
// holds either its earlier content or the complete new content, whatever happens to the run.
//
// - A writer writes to temp_path(), a temporary named `.ptmkit-tmp-PID-N.EXT` in the target's
//   folder (same file system, so the final rename is atomic; same extension, so writers that
//   pick the type from it still work), then calls commit(): the temporary is flushed to disk
//   (fsync; a close or flush error is an error) and renamed onto the target.
// - Only regular files are replaced. A target that is a device, FIFO or socket is refused
//   with an error (`--report /dev/null` never replaces /dev/null); a folder likewise.
// - Symbolic links are written through: the link stays and the file it points to is replaced
//   (atomically, in that file's folder). A link to a missing file is refused.
// - If commit() is never reached (an exception, an early return) the destructor removes the
//   temporary. A run killed outright leaves its temporaries; the next AtomicOutput in that
//   folder removes every `.ptmkit-tmp-PID-*` whose process PID no longer exists.
// - While an OutputTransaction is open, commit() only verifies and queues the file: every
//   queued file is moved into place by OutputTransaction::commit(), together, at the end. A
//   failure before then leaves every target untouched; a failure while moving files into
//   place puts back the files already replaced (kept as hard links until the end).
#pragma once

#include <filesystem>
#include <string_view>

namespace ptmkit {

// Prefix of every temporary file ptmkit creates beside an output.
inline constexpr std::string_view kTempPrefix = ".ptmkit-tmp-";

class AtomicOutput {
 public:
  explicit AtomicOutput(std::filesystem::path target);
  ~AtomicOutput();
  AtomicOutput(const AtomicOutput&) = delete;
  AtomicOutput& operator=(const AtomicOutput&) = delete;

  // Temporary path to write to. It keeps the target's extension.
  [[nodiscard]] const std::filesystem::path& temp_path() const { return temp_; }
  // The path as given (used in messages).
  [[nodiscard]] const std::filesystem::path& target() const { return target_; }
  // Flushes the temporary to disk and renames it onto the target (or queues it in the open
  // OutputTransaction). Throws ptmkit::Error naming the target on failure.
  void commit();

 private:
  std::filesystem::path target_;    // as given
  std::filesystem::path resolved_;  // after following symbolic links
  std::filesystem::path temp_;
  bool committed_ = false;
};

// Groups every output of a command: files committed while it is open reach their targets
// only in commit(). Opening one while another is open joins the outer one (its commit() and
// destructor do nothing): the outermost decides. Thread-safe (outputs may be committed from
// worker threads). Folders created by ensure_directory() while it is open are removed on
// failure if they are empty.
class OutputTransaction {
 public:
  OutputTransaction();
  ~OutputTransaction();  // without commit(): discards every queued file
  OutputTransaction(const OutputTransaction&) = delete;
  OutputTransaction& operator=(const OutputTransaction&) = delete;

  // Moves every queued file into place. On failure, restores the targets already replaced,
  // removes the rest and throws ptmkit::Error naming the file that failed.
  void commit();
  // Number of files queued so far (0 for a joined transaction).
  [[nodiscard]] std::size_t queued() const;

  // While one of these lives, commits happen at once even inside a transaction (for a writer
  // that assembles a folder of files and then renames the folder itself).
  class Immediate {
   public:
    Immediate();
    ~Immediate();
    Immediate(const Immediate&) = delete;
    Immediate& operator=(const Immediate&) = delete;
  };

 private:
  bool outermost_ = false;
  bool done_ = false;
};

// Writes a text or binary blob atomically (through AtomicOutput).
void write_file_atomic(const std::filesystem::path& path, std::string_view contents);

// Creates a folder (and parents) or throws ptmkit::Error naming it. Inside an
// OutputTransaction, the folders it creates are removed again (if empty) when the transaction
// fails.
void ensure_directory(const std::filesystem::path& dir);

// Removes `.ptmkit-tmp-PID-*` files and folders in `dir` whose process PID is gone (what a
// killed run left). Returns how many it removed. AtomicOutput and temporary_path call it once
// per folder and process.
int remove_stale_temporaries(const std::filesystem::path& dir);

// A fresh temporary name in `dir`, `.ptmkit-tmp-PID-N-HOST` + `suffix`; stale ones in `dir`
// are removed first, as by AtomicOutput.
[[nodiscard]] std::filesystem::path temporary_path(const std::filesystem::path& dir,
                                                   std::string_view suffix);

// An output that is a folder as a whole (a web export, a .ptm8 container), staged in a
// temporary folder beside `target` (`temporary_path(..., suffix)`), whose files exist at once
// even inside an OutputTransaction. commit() puts it in place of `target` in one step: an
// existing target is exchanged with it atomically (Linux renameat2 RENAME_EXCHANGE; on a
// file system without it, renamed aside first and put back on failure), then removed from
// the temporary name. Every path inside `target` holds the earlier or the new content
// whatever happens; what a kill leaves under the temporary name goes with the next run
// writing there (remove_stale_temporaries). Not committed, the staged folder is removed.
// Errors are ptmkit::Error naming the folder.
class StagedFolder {
 public:
  StagedFolder(std::filesystem::path target, std::string_view suffix);
  ~StagedFolder();
  StagedFolder(const StagedFolder&) = delete;
  StagedFolder& operator=(const StagedFolder&) = delete;

  [[nodiscard]] const std::filesystem::path& path() const { return path_; }
  void commit();

 private:
  OutputTransaction::Immediate immediate_;
  std::filesystem::path target_;
  std::filesystem::path path_;
};

}  // namespace ptmkit
