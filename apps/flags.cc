#include "flags.h"

#include <cmath>
#include <cstdlib>

#include "ptmkit/core/error.h"

namespace ptmkit::app {

namespace {

std::vector<double> parse_numbers(const std::string& text, const std::string& flag, int count,
                                  const char* shape) {
  const std::vector<std::string> items = parse_list(text, flag);
  const std::string expected =
      flag + " '" + text + "': expected " + std::to_string(count) + " numbers " + shape;
  if (static_cast<int>(items.size()) != count) throw Error(expected);
  std::vector<double> out;
  for (const std::string& item : items) {
    char* end = nullptr;
    const double v = std::strtod(item.c_str(), &end);
    if (end == item.c_str() || *end != '\0') {
      throw Error(expected + " ('" + item + "' is not a number)");
    }
    if (!std::isfinite(v)) throw Error(flag + " '" + text + "': '" + item + "' is not finite");
    out.push_back(v);
  }
  return out;
}

}  // namespace

Eigen::Vector3d parse_vector3(const std::string& text, const std::string& flag) {
  const auto v = parse_numbers(text, flag, 3, "x,y,z");
  return {v[0], v[1], v[2]};
}

Eigen::Vector2d parse_vector2(const std::string& text, const std::string& flag) {
  const auto v = parse_numbers(text, flag, 2, "x,y");
  return {v[0], v[1]};
}

std::array<int, 4> parse_box(const std::string& text, const std::string& flag) {
  const auto v = parse_numbers(text, flag, 4, "x,y,w,h");
  std::array<int, 4> box{};
  for (int i = 0; i < 4; ++i) {
    if (v[i] != std::floor(v[i]) || std::abs(v[i]) > 1e9) {
      throw Error(flag + " '" + text + "': expected whole pixels x,y,w,h");
    }
    box[i] = static_cast<int>(v[i]);
  }
  if (box[2] <= 0 || box[3] <= 0)
    throw Error(flag + " '" + text + "': width and height must be > 0");
  return box;
}

std::vector<std::string> parse_list(const std::string& text, const std::string& flag) {
  std::vector<std::string> out;
  std::size_t a = 0;
  while (a <= text.size()) {
    std::size_t b = text.find(',', a);
    if (b == std::string::npos) b = text.size();
    std::string item = text.substr(a, b - a);
    if (item.empty()) throw Error(flag + " '" + text + "': empty item");
    out.push_back(std::move(item));
    a = b + 1;
  }
  return out;
}

}  // namespace ptmkit::app
