// Atomic output: write to a temporary file beside the target, rename it over the target on
// commit(). If commit() is never reached (an exception, an early return), the destructor
// removes the temporary file, so a failed run leaves neither a partial file nor litter.
#pragma once

#include <filesystem>
#include <memory>
#include <string_view>
#include <vector>

namespace ptmkit {

class AtomicOutput {
 public:
  explicit AtomicOutput(std::filesystem::path target);
  ~AtomicOutput();
  AtomicOutput(const AtomicOutput&) = delete;
  AtomicOutput& operator=(const AtomicOutput&) = delete;

  // Temporary path to write to. It keeps the target's extension (writers that choose the file
  // type from the extension still work).
  [[nodiscard]] const std::filesystem::path& temp_path() const { return temp_; }
  [[nodiscard]] const std::filesystem::path& target() const { return target_; }
  // Renames the temporary file onto the target. Throws ptmkit::Error on failure.
  void commit();

 private:
  std::filesystem::path target_;
  std::filesystem::path temp_;
  bool committed_ = false;
};

// The outputs of one command, committed together: each is written to its own temporary path
// beside its target (add), and commit() moves them all into place once every one is written,
// so a command that fails before commit() leaves none of them (a failure among the renames
// themselves, e.g. a target folder removed meanwhile, can leave the ones renamed before it).
// Temporary files not committed are removed on destruction.
class OutputSet {
 public:
  // The path to write `target` to (its folder must exist). Throws as AtomicOutput does.
  const std::filesystem::path& add(const std::filesystem::path& target);
  // Checks that every output was written (ptmkit::Error naming the first that was not), then
  // renames each onto its target, in the order added.
  void commit();

 private:
  std::vector<std::unique_ptr<AtomicOutput>> outputs_;
};

// Writes a text or binary blob atomically.
void write_file_atomic(const std::filesystem::path& path, std::string_view contents);

// Creates a folder (and parents) or throws ptmkit::Error naming it.
void ensure_directory(const std::filesystem::path& dir);

}  // namespace ptmkit
