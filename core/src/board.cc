#include "ptmkit/core/board.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <set>
#include <string>

#include <nlohmann/json.hpp>

#include "ptmkit/core/atomic_file.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/json_file.h"
#include "ptmkit/core/limits.h"

namespace ptmkit {

namespace {

using nlohmann::json;

std::string num(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

std::string id_text(int id) {
  std::string s = "tag ";
  s.append(std::to_string(id));
  return s;
}

double cross(const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  return a.x() * b.y() - a.y() * b.x();
}

BoardTag upright_tag(int id, const Eigen::Vector2d& centre, double size) {
  const double h = 0.5 * size;
  BoardTag t;
  t.id = id;
  t.corners_mm = {centre + Eigen::Vector2d(-h, -h), centre + Eigen::Vector2d(h, -h),
                  centre + Eigen::Vector2d(h, h), centre + Eigen::Vector2d(-h, h)};
  return t;
}

void default_paper(TagBoard* board) {
  Eigen::Vector2d lo = Eigen::Vector2d::Constant(INFINITY);
  Eigen::Vector2d hi = Eigen::Vector2d::Constant(-INFINITY);
  for (const auto& t : board->tags) {
    for (const auto& c : t.corners_mm) {
      lo = lo.cwiseMin(c);
      hi = hi.cwiseMax(c);
    }
  }
  const double margin = 0.5 * board->tag_size_mm;
  board->paper_min_mm = lo.array() - margin;
  board->paper_max_mm = hi.array() + margin;
}

void sort_tags(TagBoard* board) {
  std::sort(board->tags.begin(), board->tags.end(),
            [](const BoardTag& a, const BoardTag& b) { return a.id < b.id; });
}

double number(const json& j, const char* key, const std::string& where) {
  if (!j.contains(key)) throw Error(where + ": missing \"" + key + "\"");
  const json& v = j.at(key);
  if (!v.is_number() || !std::isfinite(v.get<double>())) {
    throw Error(where + ": \"" + key + "\" must be a finite number");
  }
  return v.get<double>();
}

// Tag ids and grid sizes, range-checked in 64 bits before the conversion to int.
int integer(const json& j, const char* key, const std::string& where) {
  return json_int(j, key, -kMaxTagId, kMaxTagId, where);
}

Eigen::Vector2d point(const json& v, const std::string& what, const std::string& where) {
  if (!v.is_array() || v.size() != 2 || !v[0].is_number() || !v[1].is_number()) {
    throw Error(where + ": " + what + " must be [x, y] in mm");
  }
  const Eigen::Vector2d p(v[0].get<double>(), v[1].get<double>());
  if (!p.allFinite()) throw Error(where + ": " + what + " is not finite");
  return p;
}

}  // namespace

const BoardTag* TagBoard::find(int id) const {
  const auto it = std::lower_bound(tags.begin(), tags.end(), id,
                                   [](const BoardTag& t, int v) { return t.id < v; });
  return it != tags.end() && it->id == id ? &*it : nullptr;
}

std::string TagBoard::validate() const {
  if (family.empty()) return "no tag family";
  if (!(tag_size_mm > 0.0) || !std::isfinite(tag_size_mm)) {
    return "tag_size_mm must be a positive number, not " + num(tag_size_mm);
  }
  if (tags.empty()) return "the board has no tags";
  std::set<int> seen;
  for (const auto& t : tags) {
    if (t.id < 0) return id_text(t.id) + ": ids must be >= 0";
    if (!seen.insert(t.id).second) return "duplicate " + id_text(t.id);
    for (int k = 0; k < 4; ++k) {
      const auto& a = t.corners_mm[static_cast<std::size_t>(k)];
      const auto& b = t.corners_mm[static_cast<std::size_t>((k + 1) % 4)];
      const auto& c = t.corners_mm[static_cast<std::size_t>((k + 2) % 4)];
      if (!a.allFinite()) return id_text(t.id) + ": corner not finite";
      if (!(cross(b - a, c - b) > 0.0)) {
        return id_text(t.id) +
               ": corners must form a convex quadrilateral, counter-clockwise in the board "
               "frame (bottom-left, bottom-right, top-right, top-left)";
      }
      const double side = (b - a).norm();
      if (std::abs(side - tag_size_mm) > 0.02 * tag_size_mm) {
        return id_text(t.id) + ": a side is " + num(side) + " mm, tag_size_mm says " +
               num(tag_size_mm);
      }
      if ((a.array() < paper_min_mm.array()).any() || (a.array() > paper_max_mm.array()).any()) {
        return id_text(t.id) + ": lies outside the paper";
      }
    }
  }
  if (!std::is_sorted(tags.begin(), tags.end(),
                      [](const BoardTag& a, const BoardTag& b) { return a.id < b.id; })) {
    return "tags must be sorted by id";
  }
  return {};
}

TagBoard grid_board(const std::string& family, double tag_size_mm, int cols, int rows,
                    double spacing_mm, int first_id, const Eigen::Vector2d& centre_mm) {
  if (!(tag_size_mm > 0.0) || !std::isfinite(tag_size_mm)) {
    throw Error("board grid: tag_size_mm must be positive");
  }
  if (cols < 1 || rows < 1) throw Error("board grid: cols and rows must be at least 1");
  const long long tags = static_cast<long long>(cols) * rows;
  if (tags > kMaxBoardTags) {
    throw Error("board grid: " + std::to_string(cols) + " x " + std::to_string(rows) +
                " tags, more than the " + std::to_string(kMaxBoardTags) + " a board may have");
  }
  if (first_id > kMaxTagId - (tags - 1)) {
    throw Error("board grid: first_id " + std::to_string(first_id) + " + " + std::to_string(tags) +
                " tags passes the largest tag id " + std::to_string(kMaxTagId));
  }
  if (!(spacing_mm > tag_size_mm) || !std::isfinite(spacing_mm)) {
    throw Error("board grid: spacing_mm (centre to centre) must exceed tag_size_mm");
  }
  if (first_id < 0) throw Error("board grid: first_id must be >= 0");
  TagBoard board;
  board.family = family;
  board.tag_size_mm = tag_size_mm;
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) {
      const Eigen::Vector2d centre =
          centre_mm +
          Eigen::Vector2d((c - 0.5 * (cols - 1)) * spacing_mm, (0.5 * (rows - 1) - r) * spacing_mm);
      board.tags.push_back(upright_tag(first_id + r * cols + c, centre, tag_size_mm));
    }
  }
  default_paper(&board);
  return board;
}

TagBoard read_board_json(const std::filesystem::path& path) {
  const std::string where = path.string();
  const nlohmann::json j = read_json_object(path, "board file");
  TagBoard board;
  try {
    if (j.contains("family")) {
      if (!j["family"].is_string()) throw Error(where + ": \"family\" must be a string");
      board.family = j["family"].get<std::string>();
    }
    board.tag_size_mm = number(j, "tag_size_mm", where);
    if (!(board.tag_size_mm > 0.0)) throw Error(where + ": tag_size_mm must be positive");
    const bool has_grid = j.contains("grid");
    const bool has_tags = j.contains("tags");
    if (has_grid == has_tags) throw Error(where + ": give either \"grid\" or \"tags\"");
    if (has_grid) {
      const json& g = j["grid"];
      if (!g.is_object()) throw Error(where + ": \"grid\" must be an object");
      const int cols = integer(g, "cols", where);
      const int rows = integer(g, "rows", where);
      const double spacing = number(g, "spacing_mm", where);
      const int first_id = g.contains("first_id") ? integer(g, "first_id", where) : 0;
      const Eigen::Vector2d centre = g.contains("centre_mm")
                                         ? point(g["centre_mm"], "grid centre_mm", where)
                                         : Eigen::Vector2d::Zero();
      try {
        board = grid_board(board.family, board.tag_size_mm, cols, rows, spacing, first_id, centre);
      } catch (const Error& e) {
        throw Error(where + ": " + e.what());
      }
    } else {
      const json& tags = j["tags"];
      if (!tags.is_array()) throw Error(where + ": \"tags\" must be an array");
      if (static_cast<long long>(tags.size()) > kMaxBoardTags) {
        throw Error(where + ": " + std::to_string(tags.size()) + " tags, more than the " +
                    std::to_string(kMaxBoardTags) + " a board may have");
      }
      for (const json& t : tags) {
        if (!t.is_object()) throw Error(where + ": each tag must be an object");
        const int id = integer(t, "id", where);
        const bool by_centre = t.contains("centre_mm");
        if (by_centre == t.contains("corners_mm")) {
          throw Error(where + ": " + id_text(id) + ": give either centre_mm or corners_mm");
        }
        if (by_centre) {
          board.tags.push_back(upright_tag(
              id, point(t["centre_mm"], id_text(id) + " centre_mm", where), board.tag_size_mm));
        } else {
          const json& c = t["corners_mm"];
          if (!c.is_array() || c.size() != 4) {
            throw Error(where + ": " + id_text(id) + ": corners_mm must be 4 points");
          }
          BoardTag bt;
          bt.id = id;
          for (std::size_t k = 0; k < 4; ++k) {
            bt.corners_mm[k] = point(c[k], id_text(id) + " corner", where);
          }
          board.tags.push_back(bt);
        }
      }
      sort_tags(&board);
      if (board.tags.empty()) throw Error(where + ": the board has no tags");
      default_paper(&board);
    }
    if (j.contains("paper_mm")) {
      const json& p = j["paper_mm"];
      if (!p.is_array() || p.size() != 4) {
        throw Error(where + ": paper_mm must be [xmin, ymin, xmax, ymax]");
      }
      for (const json& v : p) {
        if (!v.is_number()) throw Error(where + ": paper_mm must be 4 numbers");
      }
      board.paper_min_mm = {p[0].get<double>(), p[1].get<double>()};
      board.paper_max_mm = {p[2].get<double>(), p[3].get<double>()};
    }
  } catch (const json::exception& e) {
    throw Error(where + ": malformed board (" + e.what() + ")");
  }
  if (const auto err = board.validate(); !err.empty()) throw Error(where + ": " + err);
  return board;
}

void write_board_json(const std::filesystem::path& path, const TagBoard& board) {
  if (const auto err = board.validate(); !err.empty()) {
    throw Error(path.string() + ": not writing an invalid board: " + err);
  }
  json j;
  j["family"] = board.family;
  j["tag_size_mm"] = board.tag_size_mm;
  j["paper_mm"] = {board.paper_min_mm.x(), board.paper_min_mm.y(), board.paper_max_mm.x(),
                   board.paper_max_mm.y()};
  json tags = json::array();
  for (const auto& t : board.tags) {
    json corners = json::array();
    for (const auto& c : t.corners_mm) corners.push_back({c.x(), c.y()});
    tags.push_back({{"id", t.id}, {"corners_mm", corners}});
  }
  j["tags"] = tags;
  write_file_atomic(path, j.dump(2) + "\n");
}

}  // namespace ptmkit
