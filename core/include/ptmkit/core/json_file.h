// Reading the project's JSON files (boards, cameras, sample planes, domes): one place for the
// errors a user sees when such a file is missing or malformed.
#pragma once

#include <filesystem>
#include <string_view>

#include <nlohmann/json.hpp>

namespace ptmkit {

// Parses `path` as a JSON object. Throws ptmkit::Error naming the file and saying what it was
// meant to be (`kind`, e.g. "camera file") when it cannot be opened, is not valid JSON, or is
// not an object.
[[nodiscard]] nlohmann::json read_json_object(const std::filesystem::path& path,
                                              std::string_view kind);

}  // namespace ptmkit
