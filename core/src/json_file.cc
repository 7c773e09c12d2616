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

}  // namespace ptmkit
