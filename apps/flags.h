// Parsing of the flag values that CLI11 does not type by itself: vectors "x,y,z", points
// "x,y", boxes "x,y,w,h" and comma-separated lists. One behaviour for every command: components
// must be finite numbers (NaN and infinity are refused here, naming the flag), nothing may follow
// the last one, and empty list items are errors.
#pragma once

#include <array>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace ptmkit::app {

// "x,y,z" -> vector. Throws ptmkit::Error naming `flag` and the text otherwise.
[[nodiscard]] Eigen::Vector3d parse_vector3(const std::string& text, const std::string& flag);
// "x,y" -> point.
[[nodiscard]] Eigen::Vector2d parse_vector2(const std::string& text, const std::string& flag);
// "x,y,w,h" -> a box in whole pixels: x, y, width, height; width and height > 0.
[[nodiscard]] std::array<int, 4> parse_box(const std::string& text, const std::string& flag);
// "a,b,c" -> {"a", "b", "c"}; at least one item, none empty.
[[nodiscard]] std::vector<std::string> parse_list(const std::string& text, const std::string& flag);

}  // namespace ptmkit::app
