// AprilTag detection against the library's own golden files on three real photographs
// (../shared/data/apriltag-photos; skipped where absent), and on rendered tags.
#include <cstdio>
#include <fstream>
#include <sstream>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "ptmkit/calib/apriltag.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/image_io.h"
#include "test_util.h"

namespace fs = std::filesystem;

namespace ptmkit::calib {
namespace {

struct Expected {
  int id = 0;
  std::array<Eigen::Vector2d, 4> corners;
  [[nodiscard]] Eigen::Vector2d centre() const {
    return (corners[0] + corners[1] + corners[2] + corners[3]) / 4.0;
  }
};

// Lines "id, (x y), (x y), (x y), (x y)".
std::vector<Expected> read_expected(const fs::path& path) {
  std::ifstream in(path);
  std::vector<Expected> out;
  std::string line;
  while (std::getline(in, line)) {
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    Expected e;
    double v[8];
    const int n = std::sscanf(line.c_str(), "%d, (%lf %lf), (%lf %lf), (%lf %lf), (%lf %lf)", &e.id,
                              &v[0], &v[1], &v[2], &v[3], &v[4], &v[5], &v[6], &v[7]);
    if (n != 9) ADD_FAILURE() << path << ": cannot parse '" << line << "'";
    // The files are in the library's pixel convention (centres at +0.5); detect_tags reports
    // OpenCV's (centres at integers).
    for (int k = 0; k < 4; ++k) e.corners[k] = {v[2 * k] - 0.5, v[2 * k + 1] - 0.5};
    out.push_back(e);
  }
  return out;
}

// The expected files were made at full resolution without edge refinement; the corner
// tolerance is the requirement's, 1.5 px (docs/TARGETS.md; our luma comes from decoded RGB rather
// than the JPEG's Y plane, which moves corners by a fraction of a pixel).
constexpr double kMaxCornerErrorPx = 1.5;

TEST(CalibAprilTag, RealPhotosMatchTheGoldenDetections) {
  const auto dir = test::shared_data("apriltag-photos");
  if (!dir) GTEST_SKIP() << "../shared/data/apriltag-photos is absent";
  TagDetectorOptions options;
  options.quad_decimate = 1.0;
  options.refine_edges = false;
  int photos = 0;
  for (const auto& entry : fs::directory_iterator(*dir)) {
    if (entry.path().extension() != ".jpg") continue;
    ++photos;
    const auto expected = read_expected(fs::path(entry.path()).replace_extension(".txt"));
    const Image img = read_image(entry.path());
    const auto found = detect_tags(img.view(), options);
    EXPECT_EQ(found.size(), expected.size()) << entry.path().filename();
    double worst = 0.0;
    for (const Expected& e : expected) {
      // The detection of the same tag: same id, nearest centre.
      const TagDetection* best = nullptr;
      for (const auto& d : found) {
        if (d.id != e.id) continue;
        if (best == nullptr ||
            (d.centre_px - e.centre()).norm() < (best->centre_px - e.centre()).norm()) {
          best = &d;
        }
      }
      ASSERT_NE(best, nullptr) << "no detection for a tag at " << e.centre().transpose();
      for (int k = 0; k < 4; ++k) {
        const double err = (best->corners_px[k] - e.corners[k]).norm();
        worst = std::max(worst, err);
        EXPECT_LE(err, kMaxCornerErrorPx) << entry.path().filename() << " corner " << k;
      }
    }
    std::printf("%s: %zu tags (expected %zu), worst corner error %.3f px\n",
                entry.path().filename().string().c_str(), found.size(), expected.size(), worst);
  }
  EXPECT_EQ(photos, 3);
}

TEST(CalibAprilTag, FamiliesParseAndBadOptionsAreErrors) {
  EXPECT_EQ(parse_tag_family("tag36h11"), TagFamily::k36h11);
  EXPECT_EQ(parse_tag_family("36h11"), TagFamily::k36h11);
  EXPECT_EQ(parse_tag_family("Standard41h12"), TagFamily::kStandard41h12);
  EXPECT_EQ(to_string(TagFamily::kCircle21h7), "tagCircle21h7");
  EXPECT_THROW((void)parse_tag_family("qr"), Error);
  TagDetectorOptions bad;
  bad.max_hamming = 5;
  const Image img(32, 32, 1);
  EXPECT_THROW((void)detect_tags(img.view(), bad), Error);
  EXPECT_THROW((void)detect_tags(Image(8, 8, 2).view()), Error);
  EXPECT_TRUE(detect_tags(img.view()).empty());  // a blank image has no tags
}

}  // namespace
}  // namespace ptmkit::calib
