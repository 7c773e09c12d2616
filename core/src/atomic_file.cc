#include "ptmkit/core/atomic_file.h"

#include <unistd.h>

#include <atomic>
#include <fstream>

#include "ptmkit/core/error.h"

namespace fs = std::filesystem;

namespace ptmkit {

namespace {
std::atomic<unsigned> g_counter{0};
}

AtomicOutput::AtomicOutput(fs::path target) : target_(std::move(target)) {
  if (target_.empty()) throw Error("output path is empty");
  const fs::path dir = target_.has_parent_path() ? target_.parent_path() : fs::path(".");
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) {
    throw Error(where(target_) + ": the folder " + dir.string() + " does not exist");
  }
  if (fs::is_directory(target_, ec)) {
    throw Error(where(target_) + ": is a folder, expected a file name");
  }
  // Hidden, unique, same folder (so rename is atomic), same extension (so writers that pick
  // the type from the extension still work).
  // Built with append: GCC 12 warns falsely (-Wrestrict) on "literal" + std::string chains.
  std::string name = ".";
  name.append(target_.stem().string())
      .append(".tmp-")
      .append(std::to_string(::getpid()))
      .append("-")
      .append(std::to_string(g_counter.fetch_add(1)))
      .append(target_.extension().string());
  temp_ = dir / name;
}

AtomicOutput::~AtomicOutput() {
  if (!committed_) {
    std::error_code ec;
    fs::remove(temp_, ec);
  }
}

void AtomicOutput::commit() {
  std::error_code ec;
  if (!fs::exists(temp_, ec)) {
    throw Error(where(target_) + ": nothing was written");
  }
  fs::rename(temp_, target_, ec);
  if (ec) {
    throw Error(where(target_) + ": cannot move the finished file into place: " + ec.message());
  }
  committed_ = true;
}

const fs::path& OutputSet::add(const fs::path& target) {
  outputs_.push_back(std::make_unique<AtomicOutput>(target));
  return outputs_.back()->temp_path();
}

void OutputSet::commit() {
  for (const auto& o : outputs_) {
    std::error_code ec;
    if (!fs::exists(o->temp_path(), ec)) throw Error(where(o->target()) + ": nothing was written");
  }
  for (const auto& o : outputs_) o->commit();
}

void write_file_atomic(const fs::path& path, std::string_view contents) {
  AtomicOutput out(path);
  {
    std::ofstream f(out.temp_path(), std::ios::binary | std::ios::trunc);
    if (!f) throw Error(where(path) + ": cannot open for writing");
    f.write(contents.data(), static_cast<std::streamsize>(contents.size()));
    f.flush();
    if (!f) throw Error(where(path) + ": write failed (disk full?)");
  }
  out.commit();
}

void ensure_directory(const fs::path& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec || !fs::is_directory(dir)) {
    throw Error(where(dir) + ": cannot create folder" + (ec ? ": " + ec.message() : ""));
  }
}

}  // namespace ptmkit
