// Reading the project's JSON files (boards, cameras, sample planes, domes): one place for the
// errors a user sees when such a file is missing or malformed.
#pragma once

#include <filesystem>
#include <string>
#include <string_view>

#include <nlohmann/json.hpp>

namespace ptmkit {

// Parses `path` as a JSON object. Throws ptmkit::Error naming the file and saying what it was
// meant to be (`kind`, e.g. "camera file") when it cannot be opened, is not valid JSON, or is
// not an object.
[[nodiscard]] nlohmann::json read_json_object(const std::filesystem::path& path,
                                              std::string_view kind);

// The integer j[key], within [lo, hi]. Throws ptmkit::Error starting with `where` and naming
// the key when it is missing, is not an integer (a string, a fraction, or a number such as
// 4.8e70 that JSON gives as a double: converting it to int would be undefined) or lies
// outside the range.
[[nodiscard]] int json_int(const nlohmann::json& j, const char* key, long long lo, long long hi,
                           const std::string& where);

}  // namespace ptmkit
