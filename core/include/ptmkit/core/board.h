// AprilTag boards: where each tag's corners lie on a flat board, in millimetres. Used to
// calibrate a camera (calib/camera.h), to find the sample plane (`ptmkit calibrate plane`)
// and to render boards with known geometry (synth/board.h).
//
// Board frame: x right, y up, z out of the board toward the viewer, millimetres; the origin is
// wherever the file puts it (a grid puts it at the grid's centre unless told otherwise).
// Tag size: the edge of the tag's black square, i.e. the outer border of the decoded region,
// which is where the apriltag library reports corners (the white quiet zone lies outside).
//
// Corner order, per tag: as the apriltag library reports them for a tag seen upright (its
// bitmap's top row toward board +y): bottom-left, bottom-right, top-right, top-left, i.e.
// counter-clockwise in the board frame.
#pragma once

#include <array>
#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace ptmkit {

struct BoardTag {
  int id = 0;
  std::array<Eigen::Vector2d, 4> corners_mm{};  // board frame, z = 0; order above
  [[nodiscard]] Eigen::Vector2d centre_mm() const {
    return 0.25 * (corners_mm[0] + corners_mm[1] + corners_mm[2] + corners_mm[3]);
  }
};

struct TagBoard {
  // Family name as the apriltag library spells it ("tag36h11"); checked by calib, which knows
  // the families (calib::parse_tag_family).
  std::string family = "tag36h11";
  double tag_size_mm = 0.0;    // edge of the black square
  std::vector<BoardTag> tags;  // sorted by id, ids unique
  // The paper's extent (board frame): white where no tag is. A board read from a file without
  // "paper_mm" gets the tags' bounding box grown by half a tag size on every side.
  Eigen::Vector2d paper_min_mm{0.0, 0.0};
  Eigen::Vector2d paper_max_mm{0.0, 0.0};

  // The tag with this id, or nullptr.
  [[nodiscard]] const BoardTag* find(int id) const;
  // Empty if valid: a family name, a size > 0, at least one tag, unique ids >= 0, every tag a
  // counter-clockwise convex quadrilateral whose sides match tag_size_mm within 2%, a paper
  // rectangle holding every tag.
  [[nodiscard]] std::string validate() const;
};

// A rows x cols grid of upright tags, centre to centre `spacing_mm`, ids row by row from
// `first_id` at the top-left tag; the grid's centre lies at `centre_mm` of the board frame.
// The paper: the tags' bounding box grown by half a tag size. Throws ptmkit::Error on
// nonsense (size <= 0, spacing <= size, no tags).
[[nodiscard]] TagBoard grid_board(const std::string& family, double tag_size_mm, int cols, int rows,
                                  double spacing_mm, int first_id = 0,
                                  const Eigen::Vector2d& centre_mm = Eigen::Vector2d::Zero());

// JSON file, either a grid
//   {"family": "tag36h11", "tag_size_mm": 20,
//    "grid": {"cols": 6, "rows": 4, "spacing_mm": 30, "first_id": 0,
//             "centre_mm": [0, 0]},                      first_id, centre_mm optional
//    "paper_mm": [xmin, ymin, xmax, ymax]}                optional
// or explicit tags, each by its centre (upright, tag_size_mm) or by its four corners:
//   {"family": "tag36h11", "tag_size_mm": 20,
//    "tags": [{"id": 0, "centre_mm": [x, y]},
//             {"id": 1, "corners_mm": [[x, y], [x, y], [x, y], [x, y]]}], ...}
// Errors (ptmkit::Error) name the file and the problem: unreadable, malformed, a size <= 0,
// duplicate or negative ids, degenerate or clockwise corners, both or neither of grid / tags.
[[nodiscard]] TagBoard read_board_json(const std::filesystem::path& path);
// Writes explicit corners (any board reads back exactly), atomically.
void write_board_json(const std::filesystem::path& path, const TagBoard& board);

}  // namespace ptmkit
