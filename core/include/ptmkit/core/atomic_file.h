// Atomic output: write to a temporary file beside the target, rename it over the target on
// commit(). If commit() is never reached (an exception, an early return), the destructor
// removes the temporary file, so a failed run leaves neither a partial file nor litter.
#pragma once

#include <filesystem>
#include <string_view>

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

// Writes a text or binary blob atomically.
void write_file_atomic(const std::filesystem::path& path, std::string_view contents);

// Creates a folder (and parents) or throws ptmkit::Error naming it.
void ensure_directory(const std::filesystem::path& dir);

}  // namespace ptmkit
