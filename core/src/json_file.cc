#include "ptmkit/core/json_file.h"

#include <fstream>
#include <string>

#include "ptmkit/core/error.h"
#include "ptmkit/core/limits.h"

namespace ptmkit {

nlohmann::json read_json_object(const std::filesystem::path& path, std::string_view kind) {
  const std::string where = path.string();
  checked_input_size(path, kMaxTextFileBytes, std::string(kind));
  std::ifstream in(path);
  if (!in) throw Error(where + ": cannot open the " + std::string(kind));
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(in);
  } catch (const nlohmann::json::exception& e) {
    throw Error(where + ": not valid JSON (" + e.what() + ")");
  }
  if (!j.is_object()) throw Error(where + ": expected a JSON object");
  return j;
}

int json_int(const nlohmann::json& j, const char* key, long long lo, long long hi,
             const std::string& where) {
  if (!j.is_object() || !j.contains(key)) throw Error(where + ": missing \"" + key + "\"");
  const nlohmann::json& v = j.at(key);
  // Appended piece by piece: GCC 12 warns (-Wrestrict, falsely) on the one-expression form.
  std::string range = "[";
  range += std::to_string(lo);
  range += ", ";
  range += std::to_string(hi);
  range += "]";
  if (!v.is_number_integer()) {
    throw Error(where + ": \"" + key + "\" must be an integer in " + range);
  }
  // Compared in 64 bits: an unsigned value beyond long long is out of any int range.
  const bool inside =
      v.is_number_unsigned()
          ? v.get<unsigned long long>() <= static_cast<unsigned long long>(hi) &&
                (lo <= 0 || v.get<unsigned long long>() >= static_cast<unsigned long long>(lo))
          : v.get<long long>() >= lo && v.get<long long>() <= hi;
  if (!inside) throw Error(where + ": \"" + key + "\" must be an integer in " + range);
  return static_cast<int>(v.get<long long>());
}

}  // namespace ptmkit
