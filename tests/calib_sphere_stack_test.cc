// Sphere calibration from the stack's evidence (sphere_stack.h): renders with what real
// photographs add (a coin beside the sphere, a reflected window, clipped highlights with
// one-sided flare streaks), refusal on weak evidence, search hints, and the real uw-psm
// chrome sphere found without any hint (skipped where the data is absent).
#include <cmath>
#include <cstdio>
#include <fstream>
#include <numbers>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "ptmkit/calib/camera.h"
#include "ptmkit/calib/dome.h"
#include "ptmkit/calib/sphere.h"
#include "ptmkit/calib/sphere_stack.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/core/light_set.h"
#include "ptmkit/core/parallel.h"
#include "ptmkit/synth/photo.h"
#include "ptmkit/synth/rig.h"
#include "test_util.h"

namespace fs = std::filesystem;

namespace ptmkit::calib {
namespace {

// The targets of docs/CALIBRATION.md's sphere-stack table: the circle's centre within 0.5 px
// and radius within 0.5%, the lights' mean error within 0.2 and the worst within 1 degree.
// Measured on these renders at most 0.006 px, 0.023%, 0.147 and 0.365 degrees; on the photo
// renders (8 lights, in memory) 0.31 px, 0.32% and a worst light of 0.51 degrees.
constexpr double kCentreTargetPx = 0.5;
constexpr double kRadiusTargetRel = 0.005;
constexpr double kLightMeanTargetDeg = 0.2;
constexpr double kLightMaxTargetDeg = 1.0;
// The photo-dome test's 8 lights: measured 0.192 deg; 0.245 with the halo's symmetry on the
// sRGB-encoded lift, 0.44 without the halo's symmetry.
constexpr double kPhotoDomeEightLightsMeanDeg = 0.25;
// The photo-chrome test's worst highlight: measured 0.29 px (0.21 with a circle of free radius
// on a cut core's arc and the halo ignored); 2.9 px when a core merged with the clipped scene
// beside it is taken whole.
constexpr double kPhotoChromeWorstHighlightPx = 1.5;

// A light's core merged with a static clipped reflection: measured 0.18 px (0.94 px for the
// same light without the reflection; 0.40 px with the disc's arc on its pixels' centres, 1.32
// px with the reflection's blurred rim taken for the light's edge); refused as "not a compact
// highlight" when the merged region is taken whole.
constexpr double kMergedWithStaticHighlightPx = 0.3;
// Holes punched next to a clipped core's outermost rows: measured 0.000 px of movement;
// 0.74 px when the holes are left for the core's opening to widen.
constexpr double kHolesInACoreMovePx = 0.1;
// A light mirrored on the edge of a window's reflection (photo-chrome seed 2, the light at
// elevation 15 degrees facing the spheres' tops): measured 0.015 and 0.004 px; 0.31 px on each
// sphere with a circle of free radius on the light's arc and the halo ignored, 1.6 and 2.4 px
// when the window's blurred rim, lifted by the light's glow, counts as the light's edge.
constexpr double kOnAWindowsEdgeHighlightPx = 0.15;
// A small core whose halo spans a mirrored window: measured 0.04 and 0.05 px; 0.37 and 0.39 px
// with the halo's symmetry measured on the sRGB-encoded lift, clipped pixels included.
constexpr double kHaloOverAWindowPx = 0.15;
// A light's core beside a lamp mirrored in the sphere that the light's glow lifts to the clip.
constexpr double kLampBesideTheCorePx = 0.3;
// A chrome core over a background much brighter on one side: measured 0.17 and 0.17 px; 0.78
// and 0.61 px by the clipped core's edge alone.
constexpr double kUnevenBackgroundPx = 0.3;
// A chrome core on a window mirrored in the sphere (clipped in the median): measured at most
// 0.27 px from the mirror highlights; 0.60 px with the window's edges in the halo.
constexpr double kLightOnAWindowPx = 0.4;
// A chrome light wholly inside a window clipped in every image, located by its glow: measured
// 0.08 px on both spheres (0.41 degrees); 5.8 px (11 degrees) from a disc cut in the window.
constexpr double kLightInAWindowPx = 0.5;
// A chrome core cut from a mirrored window that hides most of its edge (photo-chrome seed 4,
// the preset's light 3): measured 0.16 and 0.13 px on the two spheres, the worst light of the
// seed 0.25 degrees; 0.59 and 0.25 px, 1.24 degrees, with a circle of free radius fitted to the
// short arc and the halo ignored.
constexpr double kShortArcHighlightPx = 0.35;
// Chrome cores in a lit room (photo-chrome seed 2, 22 lights), located on the level set of the
// light's own lift: measured 0.054 and 0.057 px from the mirror highlights on average; 0.118
// and 0.111 px where the clip's edge is taken, which the lit scene behind moves.
constexpr double kLitChromeHighlightMeanPx = 0.09;
// The large sphere under 12 lights near the camera's axis, some of them partly hidden:
// measured (in memory) 0.56 degrees on average; 0.84 with every short arc held to the
// whole cores' radius.
constexpr double kHiddenArcsMeanDeg = 0.7;
// A candidate scoring below the default --min-score (0.5) is never taken (docs/CALIBRATION.md).
constexpr double kMinScore = 0.5;
// uw-psm's circle found without a hint against the mask's: measured 0.97 px apart (its lower
// rim is black on black).
constexpr double kFoundVsMaskCentrePx = 2.0;
// uw-psm's lights with the circle found against those with the mask's, both against the
// published lights: measured mean 2.64 against 3.10 degrees.
constexpr double kFoundVsMaskMeanDeg = 0.25;

double angle_deg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::acos(std::clamp(a.normalized().dot(b.normalized()), -1.0, 1.0)) * 180.0 /
         std::numbers::pi;
}

struct Scene {
  std::vector<Image> images;
  std::vector<fs::path> names;
  std::vector<Eigen::Vector3d> lights;
  Eigen::Vector2d centre{0.0, 0.0};
  double radius = 0.0;
};

// A 560 x 400 photo: a black glossy sphere (radius 110 px) at (190, 200); a coin (radius 70
// px) at (430, 220) whose face brightens with the light's elevation and whose relief glints
// at the same three places under different lights; a window reflected in the sphere (bright
// in every image); with `flare`, each highlight clipped and given a bright streak to one side.
Scene coin_scene(bool flare) {
  Scene s;
  s.lights = layout_directions("rings:30:8:10,50:6:20,70:4:30,90:1");
  s.centre = {190.0, 200.0};
  s.radius = 110.0;
  synth::SphereRigOptions rig;
  rig.width = 560;
  rig.height = 400;
  rig.centre_px = s.centre;
  rig.radius_px = s.radius;
  rig.background = 0.08;
  rig.body = 0.02;
  // A clipped highlight is a core a few pixels across (a 2 degree light: about 4 px here).
  rig.light_radius_deg = flare ? 2.0 : 1.0;
  rig.highlight = flare ? 3.0 : 0.9;
  rig.highlight_supersample = 16;
  rig.noise_grey = 1.0;
  const Eigen::Vector2d coin(430.0, 220.0);
  const std::array<Eigen::Vector2d, 3> glints{{{410.0, 200.0}, {450.0, 240.0}, {430.0, 190.0}}};
  for (std::size_t i = 0; i < s.lights.size(); ++i) {
    rig.light_dir = s.lights[i];
    rig.seed = i + 1;
    Image img = synth::render_sphere_rig(rig);
    for (int y = 0; y < img.height(); ++y) {
      for (int x = 0; x < img.width(); ++x) {
        float& v = img.at(x, y, 0);
        const Eigen::Vector2d p(x, y);
        if ((p - coin).norm() <= 70.0) {
          v = static_cast<float>(0.25 + 0.5 * s.lights[i].z());
          for (std::size_t g = 0; g < glints.size(); ++g) {
            if ((i + g) % 3 == 0 && (p - glints[g]).norm() <= 2.5) v = 1.0f;
          }
        }
        // A window reflected near the sphere's rim: in every image.
        if (x >= 120 && x <= 134 && y >= 150 && y <= 175) v = std::max(v, 0.95f);
        v = std::min(v, 1.0f);
      }
    }
    if (flare) {
      const Eigen::Vector3d n = (s.lights[i] + Eigen::Vector3d::UnitZ()).normalized();
      const Eigen::Vector2d h = s.centre + s.radius * Eigen::Vector2d(n.x(), -n.y());
      // Bloom: a symmetric glow (sigma 6 px) around the core.
      for (int y = 0; y < img.height(); ++y) {
        for (int x = 0; x < img.width(); ++x) {
          const double d2 = (Eigen::Vector2d(x, y) - h).squaredNorm();
          if (d2 < 400.0 && (Eigen::Vector2d(x, y) - s.centre).norm() < s.radius) {
            float& v = img.at(x, y, 0);
            v = std::min(1.0f, v + static_cast<float>(0.3 * std::exp(-d2 / 72.0)));
          }
        }
      }
      // A one-sided streak from the core, 40 px long toward the lower right, 1 px wide and
      // clipped: pulls a plain centroid of the clipped region by several pixels.
      for (int t = 1; t < 40; ++t) {
        const int x = static_cast<int>(std::lround(h.x() + 0.8 * t));
        const int y = static_cast<int>(std::lround(h.y() + 0.6 * t));
        if (x >= 0 && y >= 0 && x < img.width() && y < img.height() &&
            (Eigen::Vector2d(x, y) - s.centre).norm() < s.radius - 3) {
          img.at(x, y, 0) = 1.0f;
        }
      }
    }
    s.images.push_back(std::move(img));
    s.names.emplace_back("img" + std::to_string(i) + ".png");
  }
  return s;
}

void expect_accurate(const StackCalibration& r, const Scene& s, const char* label) {
  ASSERT_EQ(r.rig.spheres.size(), 1u);
  const Circle& c = r.rig.spheres[0].sphere;
  double mean = 0.0, max = 0.0;
  int usable = 0;
  for (std::size_t i = 0; i < s.lights.size(); ++i) {
    const RigLight& l = r.rig.lights[i];
    EXPECT_TRUE(l.found) << label << " light " << i << ": " << l.flag;
    if (!l.found) continue;
    ++usable;
    const double a = angle_deg(l.direction, s.lights[i]);
    mean += a / static_cast<double>(s.lights.size());
    max = std::max(max, a);
  }
  std::printf("%s: centre off by %.3f px, radius by %.3f%%; lights mean %.3f max %.3f deg (%d)\n",
              label, (c.centre_px - s.centre).norm(),
              100.0 * std::abs(c.radius_px - s.radius) / s.radius, mean, max, usable);
  EXPECT_LE((c.centre_px - s.centre).norm(), kCentreTargetPx) << label;
  EXPECT_LE(std::abs(c.radius_px - s.radius), kRadiusTargetRel * s.radius) << label;
  EXPECT_LE(mean, kLightMeanTargetDeg) << label;
  EXPECT_LE(max, kLightMaxTargetDeg) << label;
}

TEST(CalibSphereStack, FindsTheSphereNotTheCoinAndIgnoresTheWindow) {
  const Scene s = coin_scene(false);
  const StackCalibration r = calibrate_sphere_stack(s.images, s.names, {});
  expect_accurate(r, s, "sphere beside a coin");
  // The coin was considered and refused.
  bool coin_seen = false;
  for (const SphereCandidate& c : r.candidates) {
    if ((c.circle.centre_px - Eigen::Vector2d(430.0, 220.0)).norm() < 15.0) {
      coin_seen = true;
      EXPECT_FALSE(c.chosen);
      EXPECT_LT(c.score, kMinScore) << "coin: " << c.note;
    }
  }
  EXPECT_TRUE(coin_seen) << "the coin is round: it should be a candidate";
}

TEST(CalibSphereStack, ClippedHighlightsWithStreaksLocatedByTheirCore) {
  const Scene s = coin_scene(true);
  {
    StackCalibrationOptions given;
    given.rig.spheres = {Circle{s.centre, s.radius, {}}};
    const StackCalibration g = calibrate_sphere_stack(s.images, s.names, given);
    expect_accurate(g, s, "clipped highlights with flare streaks, circle given");
  }
  const StackCalibration r = calibrate_sphere_stack(s.images, s.names, {});
  expect_accurate(r, s, "clipped highlights with flare streaks");
  for (const SphereLight& l : r.rig.spheres[0].lights) EXPECT_TRUE(l.saturated);
}

TEST(CalibSphereStack, NoSphereIsAnErrorListingTheCandidates) {
  Scene s = coin_scene(false);
  // Paint the sphere over with the background: only the coin is left.
  for (Image& img : s.images) {
    for (int y = 0; y < img.height(); ++y) {
      for (int x = 0; x < img.width(); ++x) {
        if ((Eigen::Vector2d(x, y) - s.centre).norm() <= s.radius + 3) img.at(x, y, 0) = 0.08f;
      }
    }
  }
  try {
    (void)calibrate_sphere_stack(s.images, s.names, {});
    FAIL() << "no sphere: expected an error";
  } catch (const SphereSearchError& e) {
    EXPECT_NE(std::string(e.what()).find("candidates"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("--roi"), std::string::npos) << e.what();
    for (const SphereCandidate& c : e.candidates()) EXPECT_FALSE(c.chosen);
    // The overlay of the candidates draws on a photo.
    const Image o = candidates_overlay(s.images[0], e.candidates());
    EXPECT_EQ(o.width(), s.images[0].width());
  }
}

TEST(CalibSphereStack, HintsNarrowTheSearchAndBadHintsAreErrors) {
  const Scene s = coin_scene(false);
  StackCalibrationOptions o;
  o.search.rois = {{60, 70, 260, 260}};
  const StackCalibration boxed = calibrate_sphere_stack(s.images, s.names, o);
  expect_accurate(boxed, s, "search box");
  // A box around the coin only: the coin is refused, nothing written.
  o.search.rois = {{350, 140, 160, 160}};
  EXPECT_THROW((void)calibrate_sphere_stack(s.images, s.names, o), SphereSearchError);
  // A radius range that excludes the sphere.
  StackCalibrationOptions r;
  r.search.min_radius_px = 20.0;
  r.search.max_radius_px = 40.0;
  EXPECT_THROW((void)calibrate_sphere_stack(s.images, s.names, r), SphereSearchError);
  // A reference photo in room light (here: the sphere and coin lit evenly) adds its rim.
  test::ScratchDir dir;
  Image room(560, 400, 1, ColourSpace::kLinear, 0.4f);
  for (int y = 0; y < room.height(); ++y) {
    for (int x = 0; x < room.width(); ++x) {
      if ((Eigen::Vector2d(x, y) - s.centre).norm() <= s.radius) room.at(x, y, 0) = 0.1f;
    }
  }
  write_image(dir / "room.png", room.view());
  StackCalibrationOptions ref;
  ref.search.reference = dir / "room.png";
  expect_accurate(calibrate_sphere_stack(s.images, s.names, ref), s, "reference photo");
  write_image(dir / "small.png", Image(100, 80, 1, ColourSpace::kLinear, 0.4f).view());
  ref.search.reference = dir / "small.png";
  EXPECT_THROW((void)calibrate_sphere_stack(s.images, s.names, ref), Error);
  StackCalibrationOptions bad;
  bad.search.rois = {{2000, 2000, 50, 50}};
  EXPECT_THROW((void)calibrate_sphere_stack(s.images, s.names, bad), Error);
  bad.search.rois.clear();
  bad.search.min_radius_px = 50.0;
  bad.search.max_radius_px = 10.0;
  EXPECT_THROW((void)calibrate_sphere_stack(s.images, s.names, bad), Error);
}

TEST(CalibSphereStack, OverlayDownscaleKeepsTheLongestSideWithinTheLimit) {
  Image big(4000, 3000, 3, ColourSpace::kSRGB, 0.5f);
  double scale = 0.0;
  const Image small = downscale_for_overlay(big, 1600, &scale);
  EXPECT_LE(std::max(small.width(), small.height()), 1600);
  EXPECT_DOUBLE_EQ(scale, 1.0 / 3.0);
  const Image same = downscale_for_overlay(big, 0, &scale);
  EXPECT_EQ(same.width(), 4000);
  EXPECT_DOUBLE_EQ(scale, 1.0);
}

TEST(CalibSphereStack, LargeSphereCutByTheFrameAndHiddenByItsBase) {
  // The sphere fills most of the frame: its top 12 px are outside, a base covers its bottom.
  Scene s;
  s.lights = layout_directions("rings:30:8:10,50:6:20,70:4:30,90:1");
  s.centre = {240.3, 190.6};
  s.radius = 202.0;
  synth::SphereRigOptions rig;
  rig.width = 480;
  rig.height = 400;
  rig.centre_px = s.centre;
  rig.radius_px = s.radius;
  rig.background = 0.1;
  rig.body = 0.02;
  rig.highlight_supersample = 16;
  rig.noise_grey = 1.0;
  for (std::size_t i = 0; i < s.lights.size(); ++i) {
    rig.light_dir = s.lights[i];
    rig.seed = i + 7;
    Image img = synth::render_sphere_rig(rig);
    for (int y = 360; y < img.height(); ++y) {
      for (int x = 170; x < 310; ++x) img.at(x, y, 0) = 0.3f;
    }
    s.images.push_back(std::move(img));
    s.names.emplace_back("big" + std::to_string(i) + ".png");
  }
  const StackCalibration r = calibrate_sphere_stack(s.images, s.names, {});
  expect_accurate(r, s, "large sphere, cut by the frame, on a base");
}

TEST(CalibSphereStack, TwoSpheresWithACoinBetweenThem) {
  // Two black glossy spheres (radius 110 and 60 px) left and top right, the coin between.
  Scene left = coin_scene(false);
  synth::SphereRigOptions rig;
  rig.width = 560;
  rig.height = 400;
  rig.centre_px = {490.0, 75.0};
  rig.radius_px = 60.0;
  rig.background = 0.08;
  rig.body = 0.02;
  rig.light_radius_deg = 1.0;
  rig.highlight_supersample = 16;
  rig.noise_grey = 1.0;
  std::vector<Image> images;
  for (std::size_t i = 0; i < left.images.size(); ++i) {
    rig.light_dir = left.lights[i];
    rig.seed = 100 + i;
    const Image right = synth::render_sphere_rig(rig);
    Image img = left.images[i];
    for (int y = 0; y < img.height(); ++y) {
      for (int x = 0; x < img.width(); ++x) {
        if ((Eigen::Vector2d(x, y) - rig.centre_px).norm() <= rig.radius_px + 2.0) {
          img.at(x, y, 0) = right.at(x, y, 0);
        }
      }
    }
    images.push_back(std::move(img));
  }
  StackCalibrationOptions o;
  o.rig.sphere_count = 2;
  const StackCalibration r = calibrate_sphere_stack(images, left.names, o);
  ASSERT_EQ(r.rig.spheres.size(), 2u);
  EXPECT_LE((r.rig.spheres[0].sphere.centre_px - left.centre).norm(), kCentreTargetPx);
  EXPECT_LE((r.rig.spheres[1].sphere.centre_px - rig.centre_px).norm(), kCentreTargetPx);
  EXPECT_LE(std::abs(r.rig.spheres[1].sphere.radius_px - rig.radius_px),
            kRadiusTargetRel * rig.radius_px);
  double mean = 0.0, max = 0.0;
  for (std::size_t i = 0; i < left.lights.size(); ++i) {
    EXPECT_TRUE(r.rig.lights[i].found) << r.rig.lights[i].flag;
    const double a = angle_deg(r.rig.lights[i].direction, left.lights[i]);
    mean += a / static_cast<double>(left.lights.size());
    max = std::max(max, a);
  }
  std::printf("two spheres and a coin: lights mean %.3f max %.3f deg\n", mean, max);
  EXPECT_LE(mean, kLightMeanTargetDeg);
  EXPECT_LE(max, kLightMaxTargetDeg);
}

TEST(CalibSphereStack, SameResultWithOneOrTwoThreads) {
  const Scene s = coin_scene(true);
  StackCalibration one, two;
  {
    const ThreadLimit limit(1);
    one = calibrate_sphere_stack(s.images, s.names, {});
  }
  {
    const ThreadLimit limit(2);
    two = calibrate_sphere_stack(s.images, s.names, {});
  }
  EXPECT_EQ(one.to_json(), two.to_json());
}

TEST(CalibSphereStack, CommandRefusesWeakEvidenceAndDrawsTheCandidates) {
  test::ScratchDir dir;
  Scene s = coin_scene(false);
  std::vector<std::string> args{"calibrate", "sphere"};
  for (std::size_t i = 0; i < s.images.size(); ++i) {
    Image& img = s.images[i];
    for (int y = 0; y < img.height(); ++y) {
      for (int x = 0; x < img.width(); ++x) {
        if ((Eigen::Vector2d(x, y) - s.centre).norm() <= s.radius + 3) img.at(x, y, 0) = 0.08f;
      }
    }
    const fs::path p = dir / s.names[i];
    write_image(p, img.view());
    args.push_back(p.string());
  }
  auto run = args;
  run.insert(run.end(), {"-o", (dir / "lights.lp").string()});
  const auto r = test::run_ptmkit(run);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("candidates"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir / "lights.lp"));
  EXPECT_TRUE(fs::exists(dir / "lights.candidates.png"));
  // Malformed hints are errors too, with no output.
  for (const std::vector<std::string>& extra : {std::vector<std::string>{"--roi", "1,2,3"},
                                                {"--roi", "10,10,0,5"},
                                                {"--radius-range", "40"},
                                                {"--radius-range", "50,10"}}) {
    auto bad = args;
    bad.insert(bad.end(), extra.begin(), extra.end());
    bad.insert(bad.end(), {"-o", (dir / "bad.lp").string()});
    const auto b = test::run_ptmkit(bad);
    EXPECT_EQ(b.exit_code, 1) << extra[0] << " " << extra[1];
    EXPECT_NE(b.err.find(extra[0]), std::string::npos) << b.err;
    EXPECT_FALSE(fs::exists(dir / "bad.lp"));
  }
}

// A circle given where the photographs show no highlight (the dark ground right of the coin):
// no light is usable, the command fails saying so and names the report, which it writes
// although it fails, with every light's flag; no light file is written.
TEST(CalibSphereStack, CommandWithNoUsableLightWritesTheReportThatSaysWhy) {
  test::ScratchDir dir;
  const Scene s = coin_scene(false);
  std::vector<std::string> args{"calibrate", "sphere"};
  for (std::size_t i = 0; i < s.images.size(); ++i) {
    const fs::path p = dir / s.names[i];
    write_image(p, s.images[i].view());
    args.push_back(p.string());
  }
  const fs::path lp = dir / "lights.lp", report = dir / "report.json";
  auto run = args;
  run.insert(run.end(), {"--sphere", "525,60,25", "-o", lp.string(), "--report", report.string()});
  const auto r = test::run_ptmkit(run);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("no image has a usable highlight"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find(report.string()), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("first flag: "), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(lp));
  ASSERT_TRUE(fs::exists(report));
  std::ifstream report_file(report);
  const nlohmann::json j = nlohmann::json::parse(report_file);
  ASSERT_EQ(j.at("spheres").size(), 1u);
  const auto& lights = j.at("spheres")[0].at("lights");
  ASSERT_EQ(lights.size(), s.images.size());
  for (const auto& l : lights) {
    EXPECT_FALSE(l.at("found").get<bool>());
    EXPECT_FALSE(l.at("flag").get<std::string>().empty());
  }
  // Without --report the message says how to get one.
  auto bare = args;
  bare.insert(bare.end(), {"--sphere", "525,60,25", "-o", lp.string()});
  const auto b = test::run_ptmkit(bare);
  EXPECT_EQ(b.exit_code, 1);
  EXPECT_NE(b.err.find("--report FILE"), std::string::npos) << b.err;
  EXPECT_FALSE(fs::exists(lp));
}

// A photographic preset (synth/photo.h) rendered in memory, at `lights` (a light set) when
// given, else at the preset's own.
struct PhotoImages {
  synth::PhotoOptions options;
  synth::PhotoTruth truth;
  std::vector<Image> images;
  std::vector<fs::path> names;
};
constexpr const char* kEightLights = "rings:15:3,40:3,65:2";
// Renders every light of p->options; the images are named `prefix` and the light's index.
void render_all(PhotoImages* p, const std::string& prefix) {
  const synth::PhotoRenderer renderer(p->options);
  p->truth = renderer.truth();
  for (std::size_t i = 0; i < p->truth.light_dirs.size(); ++i) {
    p->images.push_back(renderer.render(static_cast<int>(i)));
    p->names.emplace_back(prefix + std::to_string(i) + ".jpg");
  }
}
// `width` > 0: rendered at width x height (the scene kept, the focal length scaled).
PhotoImages render_photo(const std::string& preset, const std::string& lights,
                         std::uint64_t seed = 1, std::size_t spheres = 0, int width = 0,
                         int height = 0) {
  PhotoImages p;
  p.options = synth::photo_preset_options(preset);
  if (!lights.empty()) p.options.lights = lights;
  p.options.seed = seed;
  if (spheres > 0) p.options.spheres.resize(spheres);
  if (width > 0) synth::resize_photo(width, height, &p.options);
  render_all(&p, preset);
  return p;
}
// Every channel clipped (1) within `radius` pixels of `centre`.
void paint_clipped_disc(Image* img, const Eigen::Vector2d& centre, double radius) {
  for (int y = 0; y < img->height(); ++y) {
    for (int x = 0; x < img->width(); ++x) {
      if ((Eigen::Vector2d(x, y) - centre).norm() > radius) continue;
      for (int c = 0; c < img->channels(); ++c) img->at(x, y, c) = 1.0f;
    }
  }
}
// photo-chrome in a lit room (chrome balls on bases wider than themselves, windows and lamps
// mirrored in them).
synth::PhotoOptions lit_chrome_options(std::uint64_t seed) {
  synth::PhotoOptions o = synth::photo_preset_options("photo-chrome");
  o.environment = synth::PhotoEnvironment::kLit;
  o.seed = seed;
  return o;
}
PhotoImages render_lit_chrome(std::uint64_t seed) {
  PhotoImages p;
  p.options = lit_chrome_options(seed);
  render_all(&p, "lit");
  return p;
}
// Calibrated without hints but the sphere count and the focal length.
StackCalibration calibrate_photo(const PhotoImages& p, int spheres) {
  StackCalibrationOptions o;
  o.rig.sphere_count = spheres;
  o.rig.detection.camera.focal_px = p.options.focal_px;
  return calibrate_sphere_stack(p.images, p.names, o);
}

// Every sphere's circle within the targets (the radius within `radius_rel`), every light usable,
// and the lights' mean and worst errors (degrees) within the bounds given.
void expect_photo_rig(const StackCalibration& r, const PhotoImages& p, const char* label,
                      double mean_max_deg, double worst_max_deg,
                      double radius_rel = kRadiusTargetRel) {
  ASSERT_EQ(r.rig.spheres.size(), p.truth.spheres.size()) << label;
  for (std::size_t s = 0; s < r.rig.spheres.size(); ++s) {
    const Circle& c = r.rig.spheres[s].sphere;
    const synth::SphereOutline& t = p.truth.spheres[s].outline;
    const double off = (c.centre_px - t.centre_px).norm();
    const double rel = (c.radius_px - t.radius_px) / t.radius_px;
    std::printf("%s, sphere %zu: centre off %.3f px, radius off %+.3f%%\n", label, s, off,
                100.0 * rel);
    EXPECT_LE(off, kCentreTargetPx) << label;
    EXPECT_LE(std::abs(rel), radius_rel) << label;
  }
  ASSERT_EQ(r.rig.lights.size(), p.truth.light_dirs.size()) << label;
  double sum = 0.0, worst = 0.0;
  for (std::size_t i = 0; i < r.rig.lights.size(); ++i) {
    EXPECT_TRUE(r.rig.lights[i].found) << label << " light " << i << ": " << r.rig.lights[i].flag;
    const double e = angle_deg(r.rig.lights[i].direction, p.truth.light_dirs[i]);
    sum += e;
    worst = std::max(worst, e);
  }
  const double mean = sum / static_cast<double>(r.rig.lights.size());
  std::printf("%s: %d of %zu lights usable, mean %.3f, worst %.3f degrees\n", label, r.rig.usable(),
              r.rig.lights.size(), mean, worst);
  EXPECT_EQ(r.rig.usable(), static_cast<int>(p.truth.light_dirs.size())) << label;
  EXPECT_LE(mean, mean_max_deg) << label;
  EXPECT_LE(worst, worst_max_deg) << label;
}

// A photographic preset rendered at 8 of its lights, calibrated without hints, both circles
// checked against the truth.
struct PhotoRun {
  synth::PhotoTruth truth;
  StackCalibration result;
};
PhotoRun calibrate_photo_preset(const std::string& preset) {
  const PhotoImages p = render_photo(preset, kEightLights);
  PhotoRun run{p.truth, calibrate_photo(p, 2)};
  EXPECT_EQ(run.result.rig.spheres.size(), 2u);
  for (std::size_t k = 0; k < std::min<std::size_t>(2, run.result.rig.spheres.size()); ++k) {
    const Circle& c = run.result.rig.spheres[k].sphere;
    const synth::SphereOutline& t = run.truth.spheres[k].outline;
    std::printf("%s sphere %zu: centre off %.3f px, radius off %.3f%%\n", preset.c_str(), k,
                (c.centre_px - t.centre_px).norm(),
                100.0 * std::abs(c.radius_px - t.radius_px) / t.radius_px);
    EXPECT_LE((c.centre_px - t.centre_px).norm(), kCentreTargetPx);
    EXPECT_LE(std::abs(c.radius_px - t.radius_px), kRadiusTargetRel * t.radius_px);
  }
  return run;
}

// Two black glossy spheres on cups beside the object, a coin, a dark room with windows and
// lamps reflected, flare, bloom, vignetting and noise all on.
TEST(CalibSphereStack, PhotoDomeRenderWithEveryArtefact) {
  const PhotoRun run = calibrate_photo_preset("photo-dome");
  const synth::PhotoTruth& truth = run.truth;
  const StackCalibration& r = run.result;
  ASSERT_EQ(r.rig.spheres.size(), 2u);
  for (std::size_t k = 0; k < 2; ++k) {  // never the coin
    EXPECT_GT((r.rig.spheres[k].sphere.centre_px - truth.distractor_centre_px).norm(),
              truth.distractor_radius_px);
  }
  double mean = 0.0, max = 0.0;
  for (std::size_t i = 0; i < truth.light_dirs.size(); ++i) {
    EXPECT_TRUE(r.rig.lights[i].found) << i << ": " << r.rig.lights[i].flag;
    const double a = angle_deg(r.rig.lights[i].direction, truth.light_dirs[i]);
    mean += a / static_cast<double>(truth.light_dirs.size());
    max = std::max(max, a);
  }
  // These 8 lights, rendered in memory: measured mean 0.244 deg (0.44 when small highlight
  // cores are located by their edge alone, without their halo's symmetry); the 22-light
  // JPEG preset meets the 0.2 degree mean (docs/CALIBRATION.md).
  std::printf("photo-dome lights: mean %.3f max %.3f deg\n", mean, max);
  EXPECT_LE(mean, kPhotoDomeEightLightsMeanDeg);
  EXPECT_LE(max, kLightMaxTargetDeg);
}

// A glass ball's refracted hot spot can be larger than its surface reflection, so the
// brightest-then-largest rule takes it. With two spheres the reflections agree on one
// distant light and the hot spot does not: here a saturated spot larger than the reflection
// is painted on the first sphere, away from its reflection, in one image; the reflection is
// still taken, and the report says that the second spot was.
TEST(CalibSphereStack, ASecondSpotThatAgreesWithTheOtherSphereIsTaken) {
  PhotoImages p = render_photo("photo-dome", kEightLights);
  const synth::PhotoTruth& truth = p.truth;
  const int target = 4;
  const synth::PhotoSphereTruth& s0 = truth.spheres[0];
  ASSERT_TRUE(s0.highlight_px[target].has_value());
  // The spot: on the far side of the centre from the reflection, radius 5 px (the
  // reflection's clipped core is 4-6 pixels in all).
  const Eigen::Vector2d away = (s0.outline.centre_px - *s0.highlight_px[target]).normalized();
  const Eigen::Vector2d spot = s0.outline.centre_px + 0.5 * s0.outline.radius_px * away;
  paint_clipped_disc(&p.images[target], spot, 5.0);
  const StackCalibration r = calibrate_photo(p, 2);
  ASSERT_EQ(r.rig.spheres.size(), 2u);
  const SphereLight& l = r.rig.spheres[0].lights[target];
  EXPECT_EQ(l.spot_rank, 1);
  EXPECT_GT(l.second_peak, 0.0);
  ASSERT_TRUE(l.found) << l.flag;
  EXPECT_LT((l.highlight_px - *s0.highlight_px[target]).norm(), 1.0);
  EXPECT_LE(angle_deg(r.rig.lights[target].direction, truth.light_dirs[target]),
            kLightMaxTargetDeg);
  for (std::size_t i = 0; i < truth.light_dirs.size(); ++i) {
    if (static_cast<int>(i) != target) {
      EXPECT_EQ(r.rig.spheres[0].lights[i].spot_rank, 0) << i;
    }
  }
}

// Chrome spheres with a glazed dish beside them: the dish's glint moves with the light too,
// but does not reflect the lights as the spheres do, so it is refused.
TEST(CalibSphereStack, PhotoChromeRenderRefusesTheDish) {
  PTMKIT_RELEASE_BUILD_ONLY();
  const PhotoRun run = calibrate_photo_preset("photo-chrome");
  for (const SphereCandidate& c : run.result.candidates) {
    if ((c.circle.centre_px - run.truth.distractor_centre_px).norm() <
        0.5 * run.truth.distractor_radius_px) {
      EXPECT_FALSE(c.chosen) << "the dish was taken: " << c.note;
    }
  }
  // Highlights against the mirror highlights: a chrome sphere's image of the light is a
  // clipped disc, and where the lit scene mirrored beside it is clipped too the two merge;
  // the disc is then cut out of the merged core (docs/CALIBRATION.md).
  double worst = 0.0;
  for (std::size_t k = 0; k < run.result.rig.spheres.size(); ++k) {
    const auto& lights = run.result.rig.spheres[k].lights;
    for (std::size_t i = 0; i < lights.size(); ++i) {
      const auto& truth = run.truth.spheres[k].highlight_px[i];
      if (!lights[i].found || !truth) continue;
      worst = std::max(worst, (lights[i].highlight_px - *truth).norm());
    }
  }
  std::printf("photo-chrome highlights: worst %.3f px\n", worst);
  EXPECT_LE(worst, kPhotoChromeWorstHighlightPx);
}

// In a lit room a mirror sphere shows the room's horizon as a sharp circle at about 0.7 of its
// radius, concentric with an outline that mirrors the dark cup or cloth beside it and is
// faint: the circle Hough proposes and the rim refinement used to settle on (chrome 28%, black
// glossy 30% too small). That circle reflects the low lights to below the sample plane; the
// outline keeps them all above. Chrome spheres on cups, and black glossy balls lying on the
// cloth, each in a lit room under 8 lights (3 of them 15 degrees up). At this size balls
// lying on the cloth come out 0.4-0.5% too large, so there the radius is held to 1%, five times
// closer than the horizon lies; the chrome spheres to the targets.
TEST(CalibSphereStack, SpheresInALitRoomAreNotTakenForTheirMirroredHorizon) {
  PTMKIT_RELEASE_BUILD_ONLY();
  struct Case {
    const char* preset;
    const char* material;  // nullptr: the preset's
    bool bases;
    double radius_rel;  // the radius error allowed
  };
  for (const Case& k : {Case{"photo-chrome", nullptr, true, kRadiusTargetRel},
                        Case{"photo-glass", "black-glossy", false, 0.01}}) {
    PhotoImages p;
    p.options = synth::photo_preset_options(k.preset);
    p.options.lights = kEightLights;
    p.options.environment = synth::PhotoEnvironment::kLit;
    p.options.sphere_bases = k.bases;
    if (k.material != nullptr) {
      for (synth::PhotoSphere& s : p.options.spheres) {
        s.material = synth::parse_sphere_material(k.material);
      }
    }
    render_all(&p, "lit");
    const StackCalibration r = calibrate_photo(p, 2);
    ASSERT_EQ(r.rig.spheres.size(), 2u) << k.preset;
    bool horizon_seen = false;
    for (std::size_t s = 0; s < 2; ++s) {
      const Circle& c = r.rig.spheres[s].sphere;
      const synth::SphereOutline& t = p.truth.spheres[s].outline;
      const double off = (c.centre_px - t.centre_px).norm();
      const double rel = std::abs(c.radius_px - t.radius_px) / t.radius_px;
      std::printf("%s lit, sphere %zu: centre off %.3f px, radius off %.3f%%\n", k.preset, s, off,
                  100.0 * rel);
      EXPECT_LE(off, kCentreTargetPx) << k.preset;
      EXPECT_LE(rel, k.radius_rel) << k.preset;
      EXPECT_EQ(r.rig.spheres[s].usable(), 8) << k.preset;
      // The horizon's circle is among the candidates, refused, with lights below the plane.
      for (const SphereCandidate& cand : r.candidates) {
        if ((cand.circle.centre_px - t.centre_px).norm() > 0.15 * t.radius_px) continue;
        if (std::abs(cand.circle.radius_px / t.radius_px - 0.71) > 0.06) continue;
        horizon_seen = true;
        EXPECT_FALSE(cand.chosen) << k.preset;
        EXPECT_GT(cand.below_plane_spots, 0) << k.preset;
        EXPECT_LE(cand.geometry, 0.5) << k.preset;
      }
    }
    EXPECT_TRUE(horizon_seen) << k.preset << ": the mirrored horizon was not proposed";
  }
}

// Black glossy balls lying on the cloth, dark room, 8 lights, at 1280 x 720 (analysed at full
// size): each limb mirrors the cloth the ball shades, a dark band just inside the outline, and
// the cloth brightens away from the ball. The rim search's contrast stretch clips the frame's
// darkest hundredth, here the balls' insides, and its 1 px smoothing moves such an edge toward
// the brighter skirt: circles 0.4-0.5% large, lights 0.23-0.29 degrees off on average (22
// lights, seeds 1-3). The rim taken is located again on its own rays, in linear light,
// unclipped and less smoothed: the targets.
TEST(CalibSphereStack, BlackBallsLyingOnTheClothAreNotFoundLarge) {
  PTMKIT_RELEASE_BUILD_ONLY();
  PhotoImages p;
  p.options = synth::photo_preset_options("photo-glass");
  p.options.lights = kEightLights;
  p.options.sphere_bases = false;
  for (synth::PhotoSphere& s : p.options.spheres) {
    s.material = synth::parse_sphere_material("black-glossy");
  }
  synth::resize_photo(1280, 720, &p.options);
  render_all(&p, "cloth");
  const StackCalibration r = calibrate_photo(p, 2);
  EXPECT_EQ(r.analysis_scale, 1);
  expect_photo_rig(r, p, "black balls on the cloth", kLightMeanTargetDeg, kLightMaxTargetDeg);
}

// One chrome ball in a lit room (photo-chrome with its first sphere only, 22 lights), as most
// captures hold it, found without hints or a second sphere to agree with:
// - on its cup, wider than the ball: seen from above, the cup's rim is a sharp ring 1.17 radii
//   round the ball, while the ball's limb mirrors the dark cloth it shades and shows on few
//   rays of the median. Refined onto the rim, every proposal near the ball became the cup, and
//   its lights were written 16 degrees off on average. The ball's mirror stays still under
//   every light where the cup and the cloth follow it; the still disc in the stack's spread
//   proposes the outline, refined close to it.
// - seed 2: the highlight's bloom over the mirror's dark limb outweighed, in encoded values, its
//   clipped core on the bright room mirrored beside it, and put the spot that scores the circle
//   5 px toward the limb: one light below the sample plane, and a circle 35% too large scored
//   above the ball's. A spot is centred on the light it adds, in linear light.
// - lying on the cloth, no cup: the limb was not proposed at all; a circle 3 px off and 7% small
//   was taken.
// Measured: on the cup circles 0.04-0.08 px off and 0.37-0.38% small (the mirror's last
// fraction of a pixel shows the cup beside it), lights 0.31-0.34 degrees off on average, over
// the 0.2 target; on the cloth 0.18 px and 0.27% large, lights 0.48 on average, 1.03 at worst.
TEST(CalibSphereStack, OneChromeBallInALitRoomIsNotTakenForItsCup) {
  PTMKIT_RELEASE_BUILD_ONLY();
  struct Case {
    std::uint64_t seed;
    bool bases;
    double radius_rel;
    double worst_deg;
  };
  for (const Case& k :
       {Case{1, true, kRadiusTargetRel, kLightMaxTargetDeg},
        Case{2, true, kRadiusTargetRel, kLightMaxTargetDeg}, Case{1, false, 0.01, 1.5}}) {
    PhotoImages p;
    p.options = lit_chrome_options(k.seed);
    p.options.spheres.resize(1);
    p.options.sphere_bases = k.bases;
    render_all(&p, "one");
    const StackCalibration r = calibrate_photo(p, 1);
    const std::string label = "one lit chrome ball, seed " + std::to_string(k.seed) +
                              (k.bases ? " on its cup" : " on the cloth");
    expect_photo_rig(r, p, label.c_str(), 0.5, k.worst_deg, k.radius_rel);
  }
}

// The same ball with the exposure varying by up to 1 EV from image to image (a flash whose
// output varies, a camera on automatic exposure). The ball's mirror then brightens and darkens
// with each image like its cup and the cloth:
// - against the median itself a brighter image lifted the whole mirror, and its brightest part
//   (a window mirrored by the limb) was taken for a light's reflection below the plane: the
//   ball's outline lost its geometry and the cup's rim was taken (seed 3 in memory: 8.6 px off,
//   17% large, lights 19 degrees off on average). A candidate's spots are measured against the
//   median at each image's exposure, the gains measured over its own disc.
// - lying on the cloth, the still disc was gone from the stack's spread, and the outline was
//   not proposed (seed 1: a circle 3.6 px off and 3.8% small, lights 9.9 degrees off). A
//   proposal's spread is measured again around it with the images' gains taken out.
// Measured in memory: circles 0.13-0.16 px off and 0.51-0.54% small or large; lights 0.69-0.81
// degrees off on average, 2.7-3.2 at worst (the most exposed images' highlights, merged with
// the windows they clip: not met).
TEST(CalibSphereStack, OneChromeBallUnderVaryingExposureIsNotTakenForItsCup) {
  PTMKIT_RELEASE_BUILD_ONLY();
  struct Case {
    std::uint64_t seed;
    bool bases;
  };
  for (const Case& k : {Case{3, true}, Case{1, false}}) {
    PhotoImages p;
    p.options = lit_chrome_options(k.seed);
    p.options.spheres.resize(1);
    p.options.sphere_bases = k.bases;
    p.options.artefacts.exposure_jitter_ev = 1.0;
    render_all(&p, "jitter");
    const StackCalibration r = calibrate_photo(p, 1);
    const std::string label = "one lit chrome ball, exposure +-1 EV, seed " +
                              std::to_string(k.seed) + (k.bases ? " on its cup" : " on the cloth");
    ASSERT_EQ(r.rig.spheres.size(), 1u) << label;
    const Circle& c = r.rig.spheres[0].sphere;
    const synth::SphereOutline& t = p.truth.spheres[0].outline;
    const double off = (c.centre_px - t.centre_px).norm();
    const double rel = (c.radius_px - t.radius_px) / t.radius_px;
    double sum = 0.0, worst = 0.0;
    int found = 0;
    for (std::size_t i = 0; i < r.rig.lights.size(); ++i) {
      if (!r.rig.lights[i].found) continue;
      const double e = angle_deg(r.rig.lights[i].direction, p.truth.light_dirs[i]);
      sum += e;
      worst = std::max(worst, e);
      ++found;
    }
    const double mean = found > 0 ? sum / found : 180.0;
    std::printf(
        "%s: centre off %.3f px, radius off %+.3f%%, %d lights found, mean %.3f, worst %.3f "
        "degrees\n",
        label.c_str(), off, 100.0 * rel, found, mean, worst);
    EXPECT_LE(off, kCentreTargetPx) << label;
    EXPECT_LE(std::abs(rel), 0.01) << label;
    EXPECT_GE(found, 20) << label;
    EXPECT_LE(mean, 1.5) << label;
  }
}

// The same ball on its cup, seeds 1 and 5: in the most exposed images the light's clipped
// image merges with a window mirrored beside it. Cut out of the merged region, the light was
// placed by the cut's centroid where the cut found no round edge and its halo did not settle
// (pulled toward the window), and by the midpoint of a disc and its halo where the disc was cut
// where the light's image is not round (4.5 px apart). The whole region's settled halo stands
// for the first, the halo alone for the second. Measured in memory, the worst highlight from
// its mirror highlight: seed 1 1.87 px before, 1.11 after; seed 5 2.46 before, 1.92 after
// (another light, one whose halo does not settle: not met).
TEST(CalibSphereStack, ALightMergedWithAMirroredWindowIsPlacedByItsHalo) {
  PTMKIT_RELEASE_BUILD_ONLY();
  struct Case {
    std::uint64_t seed;
    double worst_px;
  };
  for (const Case& k : {Case{1, 1.4}, Case{5, 2.2}}) {
    const std::uint64_t seed = k.seed;
    PhotoImages p;
    p.options = lit_chrome_options(seed);
    p.options.spheres.resize(1);
    p.options.artefacts.exposure_jitter_ev = 1.0;
    render_all(&p, "merged");
    const StackCalibration r = calibrate_photo(p, 1);
    const std::string label =
        "one lit chrome ball on its cup, +-1 EV, seed " + std::to_string(seed);
    ASSERT_EQ(r.rig.spheres.size(), 1u) << label;
    const auto& lights = r.rig.spheres[0].lights;
    double worst = 0.0, sum = 0.0;
    int n = 0, worst_i = -1;
    for (std::size_t i = 0; i < lights.size(); ++i) {
      const auto& truth = p.truth.spheres[0].highlight_px[i];
      if (!lights[i].found || !truth) continue;
      const double d = (lights[i].highlight_px - *truth).norm();
      sum += d;
      ++n;
      if (d > worst) {
        worst = d;
        worst_i = static_cast<int>(i);
      }
    }
    std::printf("%s: %d highlights, mean %.3f px, worst %.3f px (light %d)\n", label.c_str(), n,
                n > 0 ? sum / n : 0.0, worst, worst_i);
    EXPECT_EQ(n, static_cast<int>(lights.size())) << label;
    EXPECT_LE(worst, k.worst_px) << label;
  }
}

// Glass marbles in a lit room: the limb mirrors the floor beside the marble, which the marble
// shades, so the median of the stack shows a sharp ring at 0.91 of the radius and only a faint
// outline outside it; the mean and the maximum show the outline. Taken as the outline, that
// ring put every light 5 degrees off and nothing warned. Of two concentric rims each on most
// rays, the outer is the outline (an edge inside a sphere's outline is common: mirrored
// surroundings, the horizon); the report says which rim was passed over. The outline is
// measured on the mean, blurred by what moves in the stack: the radius is held to 1% (the
// ring is 9% off), the centre to the target.
TEST(CalibSphereStack, GlassMarblesInALitRoomAreNotTakenForTheRingInsideTheirLimb) {
  PTMKIT_RELEASE_BUILD_ONLY();
  PhotoImages p;
  p.options = synth::photo_preset_options("photo-glass");
  p.options.lights = kEightLights;
  p.options.environment = synth::PhotoEnvironment::kLit;
  render_all(&p, "glass");
  const StackCalibration r = calibrate_photo(p, 2);
  ASSERT_EQ(r.rig.spheres.size(), 2u);
  double sum = 0.0, worst = 0.0;
  int used = 0;
  for (std::size_t s = 0; s < 2; ++s) {
    const Circle& c = r.rig.spheres[s].sphere;
    const synth::SphereOutline& t = p.truth.spheres[s].outline;
    const double off = (c.centre_px - t.centre_px).norm();
    const double rel = std::abs(c.radius_px - t.radius_px) / t.radius_px;
    std::printf("glass lit, sphere %zu: centre off %.3f px, radius off %.3f%%\n", s, off,
                100.0 * rel);
    EXPECT_LE(off, kCentreTargetPx);
    EXPECT_LE(rel, 0.01);
    EXPECT_EQ(r.rig.spheres[s].usable(), 8);
  }
  for (std::size_t i = 0; i < p.truth.light_dirs.size(); ++i) {
    if (!r.rig.lights[i].found) continue;
    const double e = angle_deg(r.rig.lights[i].direction, p.truth.light_dirs[i]);
    sum += e;
    worst = std::max(worst, e);
    ++used;
  }
  ASSERT_EQ(used, 8);
  std::printf("glass lit: lights mean %.2f, worst %.2f deg\n", sum / used, worst);
  // The ring put them 5 degrees off; the targets (0.2 / 1) are not met in a lit room yet
  // (docs/CALIBRATION.md), the goal on real photographs is a mean within 1 degree.
  EXPECT_LE(sum / used, 1.0);
  int passed_over = 0;
  for (const SphereCandidate& cand : r.candidates) {
    if (cand.chosen && cand.note.find("outside a concentric rim") != std::string::npos) {
      ++passed_over;
    }
  }
  EXPECT_EQ(passed_over, 2);
}

// One black glossy sphere filling most of the frame, its top cut by the frame and its bottom
// hidden by the pedestal, in a dark room: the first circles proposed are well off, and rays
// cast from a centre that far off cross the rim obliquely; the refinement is repeated from
// its own result until the rim stops gaining support (14.7 px off after one pass). Against
// the dark room the limb fades into the background and its steepest edge lies inside the
// outline: the circle is fitted to the rim against the brighter floor (0.56 px off with the
// whole rim, 0.09 px without that part).
TEST(CalibSphereStack, PhotoLargeSphereInADarkRoomIsFound) {
  const PhotoImages p = render_photo("photo-large-sphere", "", 2);
  const synth::PhotoTruth& truth = p.truth;
  const StackCalibration r = calibrate_photo(p, 1);
  ASSERT_EQ(r.rig.spheres.size(), 1u);
  const Circle& c = r.rig.spheres[0].sphere;
  const synth::SphereOutline& t = truth.spheres[0].outline;
  const double off = (c.centre_px - t.centre_px).norm();
  const double rel = std::abs(c.radius_px - t.radius_px) / t.radius_px;
  std::printf("large sphere: centre off %.3f px, radius off %.3f%%\n", off, 100.0 * rel);
  EXPECT_LE(off, kCentreTargetPx);
  EXPECT_LE(rel, kRadiusTargetRel);
}

// photo-large-sphere rendered as `ptmkit synth` writes it (seed `seed`) and calibrated from its
// JPEG files without hints; the circle's and the lights' errors against the render's truth.
// A photographic capture rendered as `ptmkit synth` writes it (JPEG files with EXIF) into
// `dir`; returns the photographs, in light order.
std::vector<fs::path> render_photo_files(const synth::PhotoOptions& po, const fs::path& dir) {
  const synth::PhotoReport rendered = synth::render_photo_capture(po, dir);
  std::vector<fs::path> photos;
  for (const fs::path& f : rendered.files) {
    if (f.parent_path() == dir && f.filename().string().rfind("image_", 0) == 0) {
      photos.push_back(f);
    }
  }
  return photos;
}

// Chrome balls in a lit room on bases wider than themselves (photo-chrome seed 1, 22 lights),
// at a high gain (read noise of 6 grey levels), from its JPEG files: seen from above, each
// base's outer rim is a sharp ring about 1.17 radii round its ball, shifted toward the image
// centre, while the ball's own outline shows only where it lies against the base's lit top,
// and the noise on its dark limb hides the still disc that proposes the outline at the
// presets' noise. The first search refines proposals near the outlines onto the rims, and the
// two rims' highlights disagree about every light; the second search, made only then, keeps
// the outlines and chooses them by how closely their lights agree.
TEST(CalibSphereStack, SpheresWhoseFirstChoiceDisagreesAreFoundByTheSecondSearch) {
  PTMKIT_RELEASE_BUILD_ONLY();
  test::ScratchDir dir;
  PhotoImages p;
  p.options = lit_chrome_options(1);
  p.options.artefacts.read_noise_grey = 6.0;
  p.truth = synth::PhotoRenderer(p.options).truth();
  StackCalibrationOptions o;
  o.rig.sphere_count = 2;
  o.rig.detection.camera.focal_px = p.options.focal_px;
  const StackCalibration r = calibrate_sphere_stack(render_photo_files(p.options, dir.path()), o);
  EXPECT_NE(r.search_note.find("second search"), std::string::npos) << r.search_note;
  expect_photo_rig(r, p, "lit chrome, read noise 6, second search", 0.5, 1.5);
}

struct LargeSphereRun {
  StackCalibration result;
  synth::PhotoTruth truth;
  double centre_off_px = 0.0, radius_off_rel = 0.0, mean_deg = 0.0, max_deg = 0.0;
  int used = 0, visible = 0;
};

// photo-large-sphere with `po`'s changes; `visible` counts the lights whose reflection the
// camera sees.
LargeSphereRun calibrate_large_sphere(const synth::PhotoOptions& po) {
  test::ScratchDir dir;
  const std::vector<fs::path> photos = render_photo_files(po, dir.path());
  LargeSphereRun run;
  run.truth = synth::PhotoRenderer(po).truth();
  for (const auto& h : run.truth.spheres[0].highlight_px) run.visible += h.has_value() ? 1 : 0;
  StackCalibrationOptions o;
  o.rig.sphere_count = 1;
  o.rig.detection.camera.focal_px = po.focal_px;
  run.result = calibrate_sphere_stack(photos, o);
  if (run.result.rig.spheres.size() != 1) return run;
  const Circle& c = run.result.rig.spheres[0].sphere;
  const synth::SphereOutline& t = run.truth.spheres[0].outline;
  run.centre_off_px = (c.centre_px - t.centre_px).norm();
  run.radius_off_rel = std::abs(c.radius_px - t.radius_px) / t.radius_px;
  for (std::size_t i = 0; i < run.truth.light_dirs.size(); ++i) {
    if (!run.result.rig.lights[i].found) continue;
    const double a = angle_deg(run.result.rig.lights[i].direction, run.truth.light_dirs[i]);
    run.mean_deg += a;
    run.max_deg = std::max(run.max_deg, a);
    ++run.used;
  }
  if (run.used > 0) run.mean_deg /= run.used;
  return run;
}

LargeSphereRun calibrate_large_sphere(std::uint64_t seed) {
  synth::PhotoOptions po = synth::photo_preset_options("photo-large-sphere");
  po.seed = seed;
  return calibrate_large_sphere(po);
}

// Prints `run` under `label` and checks that the sphere was found within `centre_px` and
// `radius_rel` and that every light the camera sees was written, within `mean_deg` on average
// and the light target at worst.
void expect_large_sphere(const LargeSphereRun& run, const char* label, double centre_px,
                         double radius_rel, double mean_deg) {
  ASSERT_EQ(run.result.rig.spheres.size(), 1u) << label;
  std::printf(
      "large sphere, %s: centre off %.3f px, radius off %.3f%%; %d of %d visible lights, mean "
      "%.2f max %.2f deg\n",
      label, run.centre_off_px, 100.0 * run.radius_off_rel, run.used, run.visible, run.mean_deg,
      run.max_deg);
  EXPECT_LE(run.centre_off_px, centre_px) << label;
  EXPECT_LE(run.radius_off_rel, radius_rel) << label;
  EXPECT_EQ(run.used, run.visible) << label;
  EXPECT_LE(run.mean_deg, mean_deg) << label;
  EXPECT_LE(run.max_deg, kLightMaxTargetDeg) << label;
}

// The large sphere in a lit room, seed 1, from its JPEG files: against the lit wall the black
// ball brightens over its last 3-4 pixels (its reflectance rises to 1 at the limb, where it
// mirrors the wall beside it), and the steepest point of that climb lies 0.5-0.8 px inside the
// outline. Located by that steepest point the circle came out 0.38% small and the lights 0.46
// degrees off on average; located on the limb's own profile, within the targets.
TEST(CalibSphereStack, ALargeSphereAgainstALitWallIsMeasuredToItsLimb) {
  PTMKIT_RELEASE_BUILD_ONLY();
  synth::PhotoOptions po = synth::photo_preset_options("photo-large-sphere");
  po.seed = 1;
  po.environment = synth::PhotoEnvironment::kLit;
  const LargeSphereRun run = calibrate_large_sphere(po);
  expect_large_sphere(run, "lit room", 0.2, 0.0015, kLightMeanTargetDeg);
  ASSERT_FALSE(run.result.candidates.empty());
  EXPECT_NE(run.result.candidates[0].note.find("on the limb's profile"), std::string::npos)
      << run.result.candidates[0].note;
}

// The same preset, seed 3, from its JPEG files: a window mirrored along the limb has an inner
// edge a few pixels inside the outline, which a circle chosen by support within 1% of the
// radius threads together with the outline's arcs (4.1 px off, lights 2.6 degrees mean;
// 1.19 px and 0.82 degrees with the whole rim chosen within a pixel; 0.10 px and 0.19 degrees
// with the rim against brighter surroundings).
TEST(CalibSphereStack, PhotoLargeSphereWithAWindowAlongItsLimb) {
  PTMKIT_RELEASE_BUILD_ONLY();
  const LargeSphereRun run = calibrate_large_sphere(3);
  ASSERT_EQ(run.result.rig.spheres.size(), 1u);
  ASSERT_GT(run.used, 0);
  std::printf(
      "large sphere, window along the limb: centre off %.3f px, radius off %.3f%%; "
      "lights mean %.2f max %.2f deg\n",
      run.centre_off_px, 100.0 * run.radius_off_rel, run.mean_deg, run.max_deg);
  EXPECT_LE(run.centre_off_px, kCentreTargetPx);
  EXPECT_LE(run.radius_off_rel, kRadiusTargetRel);
  EXPECT_LE(run.mean_deg, kLightMeanTargetDeg);
  EXPECT_LE(run.max_deg, kLightMaxTargetDeg);
}

// Seed 5: five of the twelve lights reflect where the camera cannot see (behind the sphere,
// under its base). One sphere gives no second opinion, and what is left in those images is the
// lit scene mirrored in the sphere and JPEG noise on a bright mirrored window: spots lifting the
// sphere by 0.02-0.11 in linear light, against 0.99 for its highlights. Taken as highlights,
// three of them were written as lights 35-61 degrees off. Every hidden light is dropped, saying
// why, and every light written is within the targets.
TEST(CalibSphereStack, ALightHiddenFromTheCameraIsNotTakenFromTheLitScene) {
  PTMKIT_RELEASE_BUILD_ONLY();
  const LargeSphereRun run = calibrate_large_sphere(5);
  ASSERT_EQ(run.result.rig.spheres.size(), 1u);
  // One exposure throughout and a still camera: the lit scene under each light is neither a
  // change of exposure nor a shift.
  EXPECT_TRUE(run.result.exposure_gains.empty());
  EXPECT_TRUE(run.result.image_shifts_px.empty());
  const SphereReport& sphere = run.result.rig.spheres[0];
  int hidden = 0;
  for (std::size_t i = 0; i < run.truth.light_dirs.size(); ++i) {
    const bool visible = run.truth.spheres[0].highlight_px[i].has_value();
    if (visible) {
      EXPECT_TRUE(run.result.rig.lights[i].found) << "light " << i << ": " << sphere.lights[i].flag;
      continue;
    }
    ++hidden;
    EXPECT_FALSE(run.result.rig.lights[i].found) << "light " << i << " is hidden from the camera";
    EXPECT_NE(sphere.lights[i].flag.find("no highlight on the sphere"), std::string::npos)
        << sphere.lights[i].flag;
  }
  EXPECT_EQ(hidden, 5);
  std::printf("large sphere, 5 lights hidden: %d lights written, mean %.2f max %.2f deg\n",
              run.used, run.mean_deg, run.max_deg);
  EXPECT_EQ(run.used, 7);
  EXPECT_LE(run.max_deg, kLightMaxTargetDeg);
}

// A glass ball of 180 px in a lit room, seed 4. Glass focuses each light it lets in into a
// glow on its far side; a light that reflects where the base hides it leaves only that glow,
// at the limb. Counted as a light's reflection below the sample plane, the glow cost the
// outline's circle its geometry (0.75), and a circle 10 px inside it that put no light below
// was kept in its place; a circle 45% too large then scored above that one, and its lights were
// written 59 degrees off on average. On a large glass ball a spot that is unclipped beside
// clipped reflections, or far broader or smaller than they are, is no reflection.
TEST(CalibSphereStack, AGlassBallsGlowDoesNotShrinkItsOutline) {
  PTMKIT_RELEASE_BUILD_ONLY();
  synth::PhotoOptions po = synth::photo_preset_options("photo-large-sphere");
  po.seed = 4;
  po.environment = synth::PhotoEnvironment::kLit;
  for (synth::PhotoSphere& sp : po.spheres) sp.material = synth::SphereMaterial::kGlass;
  const LargeSphereRun run = calibrate_large_sphere(po);
  expect_large_sphere(run, "glass, lit room", kCentreTargetPx, kRadiusTargetRel,
                      kLightMeanTargetDeg);
  EXPECT_EQ(run.result.material, SphereMaterial::kGlass) << run.result.material_note;
}

// The same glass ball in a dark room, seed 1: five lights reflect where the camera cannot see
// them, and in three of their images the brightest spot is the glow, a clipped region many
// times a reflection's size (or, at the limb, an unclipped one). With the outline found, the
// glow's clipped core taken as the highlight was written as a light 89 degrees off. Glow is
// told by its size against the ball's reflections and never taken: every hidden light is
// flagged, and every light written is a reflection (the circle here is 0.5% small, which leaves
// the lights about 0.6 degrees off; a glow is tens).
TEST(CalibSphereStack, AGlassBallsGlowIsNeverTakenForALight) {
  PTMKIT_RELEASE_BUILD_ONLY();
  synth::PhotoOptions po = synth::photo_preset_options("photo-large-sphere");
  po.seed = 1;
  for (synth::PhotoSphere& sp : po.spheres) sp.material = synth::SphereMaterial::kGlass;
  const LargeSphereRun run = calibrate_large_sphere(po);
  ASSERT_EQ(run.result.rig.spheres.size(), 1u);
  const SphereReport& sphere = run.result.rig.spheres[0];
  int glow_flags = 0;
  for (std::size_t i = 0; i < run.truth.light_dirs.size(); ++i) {
    const bool visible = run.truth.spheres[0].highlight_px[i].has_value();
    EXPECT_EQ(run.result.rig.lights[i].found, visible)
        << "light " << i << ": " << sphere.lights[i].flag;
    if (sphere.lights[i].flag.find("refracted hot spot's glow") != std::string::npos) ++glow_flags;
  }
  std::printf(
      "glass ball, dark room: %d of %d visible lights written, mean %.2f max %.2f deg; %d "
      "flagged as glow\n",
      run.used, run.visible, run.mean_deg, run.max_deg, glow_flags);
  EXPECT_GE(glow_flags, 1);
  EXPECT_LE(run.max_deg, 2.0);
}

// A dark room photographed at a high gain: read noise of 6 grey levels (0.056 in the JPEG's
// sRGB values on the black ball and the room; the presets' is 1). Some pixel of any small disc
// then rises 0.2-0.28 above the stack's median in every image, and a 16 px circle that Hough
// drew in the noise had a "moving spot" at its own place in each image: it was taken for the
// sphere and its noise written as lights (62 degrees off on average). A spot must now rise
// six times the disc's noise above the median: the 180 px sphere is found and its seven
// visible lights are written (measured: centre 0.83 px, radius 0.41%, mean 0.43, worst 0.61
// degrees; noise this strong moves the outline's edge points).
TEST(CalibSphereStack, ANoisyDarkRoomDoesNotMakeACircleOfNoiseASphere) {
  PTMKIT_RELEASE_BUILD_ONLY();
  synth::PhotoOptions po = synth::photo_preset_options("photo-large-sphere");
  po.artefacts.read_noise_grey = 6.0;
  expect_large_sphere(calibrate_large_sphere(po), "read noise 6", 1.0, 0.005, 0.6);
}

// A camera left on automatic exposure (or a flash whose output varies): each image 2^u times
// the stack's exposure, u uniform in [-1, 1]. The spots were measured against the stack's
// median as it is, so an image exposed 1.46 times showed the lit scene mirrored in the large
// sphere lifted like a highlight, and a light the camera does not see was written 90 degrees
// off (8 lights for 7 visible); and the cores of the most exposed images, a star flare whose
// spokes join, were cut back to the stack's usual core, off their centre (2-3 degrees). Each
// image's exposure is now measured from what the sphere mirrors of the room, the median
// scaled by it before the lift is taken, and a core compared with the cores of images exposed
// about as much: the seven visible lights are written and no other (measured: mean 0.17,
// worst 0.20 degrees; the gains follow the render's factors within 7%).
TEST(CalibSphereStack, ExposureThatVariesFromImageToImageIsMeasuredFromTheRoom) {
  PTMKIT_RELEASE_BUILD_ONLY();
  synth::PhotoOptions po = synth::photo_preset_options("photo-large-sphere");
  po.seed = 2;
  po.artefacts.exposure_jitter_ev = 1.0;
  const LargeSphereRun run = calibrate_large_sphere(po);
  expect_large_sphere(run, "exposure jitter 1 EV", 0.5, 0.005, 0.3);
  if (run.result.rig.spheres.size() != 1) return;
  EXPECT_LE(run.max_deg, 0.5);
  EXPECT_TRUE(run.result.image_shifts_px.empty()) << "an exposure change is no camera shift";
  // The gains are the render's factors up to one common scale (the stack's own exposure).
  const std::vector<double>& g = run.result.exposure_gains;
  ASSERT_EQ(g.size(), run.truth.light_dirs.size());
  std::vector<double> scale;
  for (std::size_t i = 0; i < g.size(); ++i) {
    if (g[i] != 1.0) scale.push_back(g[i] / synth::exposure_factor(po, static_cast<int>(i)));
  }
  ASSERT_GE(scale.size(), g.size() - 2);
  std::sort(scale.begin(), scale.end());
  const double mid = scale[scale.size() / 2];
  for (double v : scale) EXPECT_NEAR(v / mid, 1.0, 0.08);
}

// A camera that moves by a fraction of a pixel between shots (each image shifted by up to
// half a pixel) moves every edge of the scene: against the stack's median each bright edge of
// a window mirrored in the large sphere lifted like a moving spot in every image, and a 19 px
// circle with such "spots" was taken for the sphere (6 lights written, 82 degrees off on
// average; seed 1 refused). A moving spot must now rise above the median's maximum over each
// pixel's 3 x 3 neighbourhood: the sphere is found and its seven visible lights written
// (measured: mean 0.24, worst 0.46 degrees; a shift of half a pixel turns a light by up to
// 0.3 degrees on this 180 px sphere, and nothing here undoes it).
TEST(CalibSphereStack, ACameraThatMovedBetweenShotsDoesNotMakeEdgesSpots) {
  PTMKIT_RELEASE_BUILD_ONLY();
  synth::PhotoOptions po = synth::photo_preset_options("photo-large-sphere");
  po.seed = 2;
  po.artefacts.shake_px = 0.5;
  const LargeSphereRun run = calibrate_large_sphere(po);
  expect_large_sphere(run, "shake 0.5 px", 0.5, 0.005, 0.4);
  if (run.result.rig.spheres.size() != 1) return;
  // The shifts are reported, as the render made them up to their common mean (the median the
  // shifts are measured against sits near the images' mean position).
  const std::vector<Eigen::Vector2d>& d = run.result.image_shifts_px;
  ASSERT_EQ(d.size(), run.truth.light_dirs.size());
  const synth::ShakeError e = synth::shake_error(po, d);
  std::printf("shifts found within %.3f px rms of the render's\n", e.rms_px);
  EXPECT_LE(e.rms_px, 0.15);
}

// The same shake on the photo-dome's 42 px spheres, where half a pixel turns a light by up to
// 1.4 degrees: each highlight is taken back into the stack's frame by its image's measured
// shift (8 lights, in memory: lights mean 0.52, worst 0.97 degrees; 1.01 and 1.69 with the
// highlights left where they lie in each image). With eight images the shifts are measured
// less well than with 22 (the bench's 22-light renders: means 0.32-0.35).
TEST(CalibSphereStack, HighlightsOfACameraThatMovedAreTakenBackByItsShift) {
  PTMKIT_RELEASE_BUILD_ONLY();
  PhotoImages p;
  p.options = synth::photo_preset_options("photo-dome");
  p.options.lights = kEightLights;
  p.options.artefacts.shake_px = 0.5;
  render_all(&p, "dome");
  const StackCalibration r = calibrate_photo(p, 2);
  EXPECT_EQ(r.image_shifts_px.size(), p.truth.light_dirs.size()) << "the camera moved";
  expect_photo_rig(r, p, "photo-dome shaken by up to 0.5 px", 0.6, 1.0);
}

// Chrome spheres at three times the presets' exposure (8 lights): every light's clipped core
// is a disc of bloom of 300-390 pixels (6-7% of the sphere) and 10-12% of it above half its
// lift, one size in every image. Those spots were refused as not compact when finding the
// spheres (over 10% of the disc), and the cores when locating the lights (over 2% of the
// sphere): other circles were taken (34 px off, lights 53 degrees off on average), and with
// the circles given no light was usable. Clipped spots of the sphere's one bloom size, and
// clipped cores up to 1.5 times its usual one, are compact: both spheres are found and every
// light is written (measured: mean 0.57, worst 0.90 degrees; the clipped discs' centres lie
// 0.2-0.45 px outward of the mirror highlights).
TEST(CalibSphereStack, AnOverexposedChromeSphereKeepsItsBloomedCores) {
  PTMKIT_RELEASE_BUILD_ONLY();
  PhotoImages p;
  p.options = synth::photo_preset_options("photo-chrome");
  p.options.exposure = 3.0;
  p.options.lights = kEightLights;
  render_all(&p, "chrome");
  const StackCalibration r = calibrate_photo(p, 2);
  expect_photo_rig(r, p, "chrome at exposure 3", 0.75, 1.25);
  // Each light's disc of bloom changes much of each sphere: against the median the images
  // seem shifted (by 0.11 px, the median over them), but the shifts measured on the frame's
  // halves alone lie 0.25 px apart, and a camera moves the whole frame alike.
  EXPECT_TRUE(r.image_shifts_px.empty()) << "a steady camera reported as moved";
}

// One glass marble: no second sphere to agree with, and in some images its refracted hot
// spot is the brighter and larger spot. Where the spot taken is unusable (not compact, or
// reflecting to below the plane) and a comparable second spot is usable, the second is taken
// and stays doubtful: every light is usable and none is the hot spot.
TEST(CalibSphereStack, OneGlassMarbleHasEveryLight) {
  PTMKIT_RELEASE_BUILD_ONLY();
  const PhotoImages p = render_photo("photo-glass", "", 1, 1);
  const StackCalibration r = calibrate_photo(p, 1);
  ASSERT_EQ(r.rig.spheres.size(), 1u);
  double mean = 0.0, max = 0.0;
  int second = 0;
  for (std::size_t i = 0; i < p.truth.light_dirs.size(); ++i) {
    const SphereLight& l = r.rig.spheres[0].lights[i];
    EXPECT_TRUE(l.found) << i << ": " << l.flag;
    if (l.spot_rank == 1) {
      ++second;
      EXPECT_GT(l.second_peak, 0.0) << i;
    }
    const double a = angle_deg(r.rig.lights[i].direction, p.truth.light_dirs[i]);
    mean += a / static_cast<double>(p.truth.light_dirs.size());
    max = std::max(max, a);
  }
  std::printf("one glass marble: %d lights from the second spot; mean %.3f max %.3f deg (%s)\n",
              second, mean, max, r.material_note.c_str());
  EXPECT_GE(second, 1);
  EXPECT_LE(max, kLightMaxTargetDeg);
  EXPECT_EQ(r.material, SphereMaterial::kGlass);

  // Told it is a mirror, the same marble's unusable spots leave their lights without one:
  // another spot is never taken in their place.
  StackCalibrationOptions mirror;
  mirror.rig.sphere_count = 1;
  mirror.rig.detection.camera.focal_px = p.options.focal_px;
  mirror.material = SphereMaterial::kMirror;
  const StackCalibration m = calibrate_sphere_stack(p.images, p.names, mirror);
  EXPECT_EQ(m.material, SphereMaterial::kMirror);
  int unusable = 0;
  for (const SphereLight& l : m.rig.spheres[0].lights) {
    EXPECT_EQ(l.spot_rank, 0);
    unusable += l.found ? 0 : 1;
  }
  // At least the lights glass took from the second spot; as glass, a compact component is
  // also preferred within the first spot's window, which settles one more here.
  EXPECT_GE(unusable, second);
}

// The material is decided from where the second spots lie: a glass ball's refracted hot spot
// is across the centre from its reflection. Glass marbles are found to be glass, and once the
// two marbles settle which spot is each light's reflection no light is left doubtful; black
// glossy spheres (no second spots) and chrome ones are mirrors.
TEST(CalibSphereStack, SphereMaterialDecidedFromTheSecondSpots) {
  PTMKIT_RELEASE_BUILD_ONLY();
  const PhotoImages glass = render_photo("photo-glass", kEightLights);
  const StackCalibration g = calibrate_photo(glass, 2);
  std::printf("photo-glass: %s, %s\n", to_string(g.material), g.material_note.c_str());
  EXPECT_EQ(g.material, SphereMaterial::kGlass);
  EXPECT_GE(g.two_spot_images, 2);
  EXPECT_EQ(g.rig.usable(), static_cast<int>(glass.truth.light_dirs.size()));
  EXPECT_EQ(g.rig.outliers(), 0);
  const PhotoImages chrome = render_photo("photo-chrome", kEightLights);
  const StackCalibration c = calibrate_photo(chrome, 2);
  std::printf("photo-chrome: %s, %s\n", to_string(c.material), c.material_note.c_str());
  EXPECT_EQ(c.material, SphereMaterial::kMirror);
}

// A static reflection clipped in every image (a window or a lamp mirrored in the chrome),
// thicker than the light's core and touching it in one image: the clipped region there is
// mostly the reflection. The light's core is still the part that is not clipped in the
// stack's median, and its centre is found from its own edge.
TEST(CalibSphereStack, ACoreMergedWithAStaticClippedReflectionIsCutFromIt) {
  PTMKIT_RELEASE_BUILD_ONLY();
  PhotoImages p = render_photo("photo-chrome", kEightLights);
  const synth::PhotoTruth& truth = p.truth;
  const int target = 4;
  const synth::PhotoSphereTruth& s0 = truth.spheres[0];
  ASSERT_TRUE(s0.highlight_px[target].has_value());
  // The reflection: a clipped disc of radius 6 px (the light's core is about 4), overlapping
  // the core by about a pixel on the side toward the sphere's centre, in every image.
  const Eigen::Vector2d toward = (s0.outline.centre_px - *s0.highlight_px[target]).normalized();
  const Eigen::Vector2d blob = *s0.highlight_px[target] + 9.0 * toward;
  for (Image& img : p.images) paint_clipped_disc(&img, blob, 6.0);
  const StackCalibration r = calibrate_photo(p, 2);
  ASSERT_EQ(r.rig.spheres.size(), 2u);
  const SphereLight& l = r.rig.spheres[0].lights[target];
  ASSERT_TRUE(l.found) << l.flag;
  const double off = (l.highlight_px - *s0.highlight_px[target]).norm();
  std::printf("core beside a static clipped reflection: %.3f px from the mirror highlight\n", off);
  EXPECT_LT(off, kMergedWithStaticHighlightPx);
}

// Each of the two spheres' highlights of light `target` within `bound_px` of the truth's
// mirror highlight.
void expect_highlight_near_truth(const StackCalibration& r, const PhotoImages& p,
                                 std::size_t target, const char* label, double bound_px) {
  ASSERT_EQ(r.rig.spheres.size(), 2u) << label;
  for (std::size_t k = 0; k < 2; ++k) {
    const auto& truth = p.truth.spheres[k].highlight_px[target];
    ASSERT_TRUE(truth.has_value()) << label;
    const SphereLight& l = r.rig.spheres[k].lights[target];
    ASSERT_TRUE(l.found) << label << ": " << l.flag;
    const double off = (l.highlight_px - *truth).norm();
    std::printf("sphere %zu, %s: %.3f px from the mirror highlight\n", k, label, off);
    EXPECT_LT(off, bound_px) << label;
  }
}

// A light mirrored beside a window, its clipped core merged with the window's in that image:
// the cut keeps a short arc of the light's edge. On so short an arc a free circle's radius
// trades for its centre; the arc is fitted with the radius of the sphere's whole cores, and the
// halo over the dark around the light, which errs otherwise, is averaged in. Every light of the
// preset (22) is checked against the targets.
TEST(CalibSphereStack, ACoreCutToAShortArcKeepsTheRadiusOfTheWholeCores) {
  PTMKIT_RELEASE_BUILD_ONLY();
  const PhotoImages p = render_photo("photo-chrome", "", 4);
  const StackCalibration r = calibrate_photo(p, 2);
  expect_photo_rig(r, p, "photo-chrome seed 4", kLightMeanTargetDeg, kLightMaxTargetDeg);
  expect_highlight_near_truth(r, p, 3, "core cut to a short arc", kShortArcHighlightPx);
}

// The large sphere under lights near the camera's axis: the camera's reflection and the
// pedestal hide part of some lights' images, and the arcs left of them fit circles 21-29%
// larger than the sphere's whole cores. Such an arc keeps its own circle: held to the whole
// cores' radius those highlights went 3-4 px off.
TEST(CalibSphereStack, AShortArcThatDisagreesWithTheWholeCoresKeepsItsOwnCircle) {
  PTMKIT_RELEASE_BUILD_ONLY();
  const PhotoImages p = render_photo("photo-large-sphere", "rings:15:3,40:3,65:2,80:4", 1);
  const StackCalibration r = calibrate_photo(p, 1);
  ASSERT_EQ(r.rig.spheres.size(), 1u);
  double sum = 0.0, worst = 0.0;
  int n = 0;
  for (std::size_t i = 0; i < r.rig.lights.size(); ++i) {
    if (!r.rig.lights[i].found) continue;
    const double e = angle_deg(r.rig.lights[i].direction, p.truth.light_dirs[i]);
    sum += e;
    worst = std::max(worst, e);
    ++n;
  }
  ASSERT_GT(n, 0);
  std::printf("large sphere under high lights: %d lights, mean %.3f, worst %.3f degrees\n", n,
              sum / n, worst);
  EXPECT_LE(sum / n, kHiddenArcsMeanDeg);
}

// A photographic preset at 10 lights (elevation 15 degrees at azimuths 0, 90, 180, 270; 40 at
// the same; 65 at 0 and 180), calibrated without hints; each sphere's highlight of light
// `target` is checked against the truth.
void check_light(const std::string& preset, std::uint64_t seed, int target, const char* label,
                 double bound_px) {
  const PhotoImages p = render_photo(preset, "rings:15:4,40:4,65:2", seed);
  expect_highlight_near_truth(calibrate_photo(p, 2), p, static_cast<std::size_t>(target), label,
                              bound_px);
}

// A chrome sphere mirrors a window, clipped in every image but with a blurred rim that is
// not; one light's image lies on that rim, its clipped core merged with the window's. The
// light's edge is taken only where the median is dark: the window's rim, lifted by the
// light's glow, would pull the disc into the window.
// (Seed 2: the light at elevation 15 degrees facing the spheres' tops, the preset's own
// light 3, is mirrored beside a window on both spheres.)
TEST(CalibSphereStack, ACoreOnAWindowsBlurredRimIsCutFromTheWindow) {
  PTMKIT_RELEASE_BUILD_ONLY();
  check_light("photo-chrome", 2, 1, "core on a window's rim", kOnAWindowsEdgeHighlightPx);
}

// A black glossy sphere's small clipped core beside a window mirrored in the sphere: the halo
// spans the window, where the light adds to a bright background. Its symmetry is measured on
// the lift in linear light and without clipped pixels; on the sRGB-encoded lift the halo over
// the window looks weaker and the centre moves away from it.
TEST(CalibSphereStack, AHaloOverAMirroredWindowIsMeasuredInLinearLight) {
  PTMKIT_RELEASE_BUILD_ONLY();
  check_light("photo-dome", 2, 1, "halo over a mirrored window", kHaloOverAWindowPx);
}

// A chrome sphere's clipped core where the background is much brighter on one side (seed 1,
// the light at elevation 15 degrees facing the spheres' bottoms): the clip is reached further
// out on that side, and the core's edge moves; its halo's symmetry does not.
TEST(CalibSphereStack, ACoreOverAnUnevenBackgroundIsCentredByItsHalo) {
  PTMKIT_RELEASE_BUILD_ONLY();
  check_light("photo-chrome", 1, 3, "core over an uneven background", kUnevenBackgroundPx);
}

// The mean distance (px) of sphere k's usable highlights from the truth's mirror highlights.
double mean_highlight_off_px(const StackCalibration& r, const PhotoImages& p, std::size_t k) {
  double sum = 0.0;
  int n = 0;
  const auto& lights = r.rig.spheres[k].lights;
  for (std::size_t i = 0; i < lights.size(); ++i) {
    const auto& truth = p.truth.spheres[k].highlight_px[i];
    if (!lights[i].found || !truth) continue;
    sum += (lights[i].highlight_px - *truth).norm();
    ++n;
  }
  return n > 0 ? sum / n : 1e9;
}

// Chrome spheres in a lit room: the light's clipped image sits on the room mirrored in the
// sphere, brighter on one side than the other, so the clip is reached further out there. Each
// core is centred on the set where the light's own lift (above the stack's median, in linear
// light) passes a level that every clipped pixel is known to pass, which the background does
// not move.
TEST(CalibSphereStack, ChromeCoresInALitRoomAreCentredOnTheLightsOwnLift) {
  PTMKIT_RELEASE_BUILD_ONLY();
  const PhotoImages p = render_lit_chrome(2);
  const StackCalibration r = calibrate_photo(p, 2);
  ASSERT_EQ(r.rig.spheres.size(), 2u);
  EXPECT_EQ(r.rig.usable(), static_cast<int>(p.truth.light_dirs.size()));
  for (std::size_t k = 0; k < 2; ++k) {
    const double off = mean_highlight_off_px(r, p, k);
    std::printf("lit chrome, sphere %zu: highlights %.3f px from the mirror highlights\n", k, off);
    EXPECT_LT(off, kLitChromeHighlightMeanPx);
  }
}

// Chrome spheres in a lit room (seed 1, 1280 x 720, 11 of the preset's 22 lights): two lights
// fall on a window mirrored in both spheres, clipped in the stack's median. The light's clipped
// core merges with the window's, and the window's blurred edges, lifted unevenly by the
// light's glow, are no part of the light's halo: the halo's symmetry is measured over the dark
// surroundings only. Measured 0.02-0.27 px from the mirror highlights; 0.16-0.60 px with the
// window's edges in the halo.
TEST(CalibSphereStack, ALightOnAMirroredWindowIsCentredByTheHaloOverTheDarkAroundIt) {
  PTMKIT_RELEASE_BUILD_ONLY();
  PhotoImages p;
  p.options = lit_chrome_options(1);
  synth::resize_photo(1280, 720, &p.options);
  // Every other light (11 of 22), lights 6 and 14 among them, as 3 and 7.
  const std::vector<Eigen::Vector3d> all = synth::resolve_lights(p.options);
  for (std::size_t i = 0; i < all.size(); i += 2) p.options.light_dirs.push_back(all[i]);
  render_all(&p, "lit");
  const StackCalibration r = calibrate_photo(p, 2);
  ASSERT_EQ(r.rig.spheres.size(), 2u);
  for (const int light : {3, 7}) {
    for (std::size_t k = 0; k < 2; ++k) {
      const auto& truth = p.truth.spheres[k].highlight_px[static_cast<std::size_t>(light)];
      ASSERT_TRUE(truth.has_value());
      const SphereLight& l = r.rig.spheres[k].lights[static_cast<std::size_t>(light)];
      ASSERT_TRUE(l.found) << l.flag;
      const double off = (l.highlight_px - *truth).norm();
      std::printf("light %d on a window, sphere %zu: %.3f px from the mirror highlight\n", light, k,
                  off);
      EXPECT_LT(off, kLightOnAWindowPx);
    }
  }
}

// Chrome spheres in a lit room (seed 7, 640 x 360): light 3 falls inside a window mirrored in
// both spheres, clipped in every image; only its glow shows beyond the window. Its core merges
// with the window and is located again as a disc of the sphere's usual core; with none of the
// light's edge to pin it, that disc is placed by the window's shape, and its halo does not settle
// near it. The location found first (the whole region's, moved to its halo's centre over the
// dark around it) then stands: the disc's centre was 5-6 px off, and as both spheres took it
// (from the JPEG files) the light was written 11.5 degrees off.
TEST(CalibSphereStack, ALightInsideAMirroredWindowIsNotTakenAtTheWindowsCentre) {
  PTMKIT_RELEASE_BUILD_ONLY();
  const PhotoImages p = render_lit_chrome(7);
  const StackCalibration r = calibrate_photo(p, 2);
  constexpr std::size_t kInWindow = 3;
  expect_highlight_near_truth(r, p, kInWindow, "light in a window", kLightInAWindowPx);
  ASSERT_EQ(r.rig.lights.size(), p.truth.light_dirs.size());
  const double err = angle_deg(r.rig.lights[kInWindow].direction, p.truth.light_dirs[kInWindow]);
  std::printf("light in a window: %.3f degrees off\n", err);
  EXPECT_LE(err, kLightMaxTargetDeg);
}

std::vector<Eigen::Vector3d> published_lights(const fs::path& root) {
  std::ifstream lf(root / "lights.txt");
  int n = 0;
  lf >> n;
  std::vector<Eigen::Vector3d> v(static_cast<std::size_t>(n));
  for (auto& d : v) lf >> d.x() >> d.y() >> d.z();
  return v;
}

TEST(CalibSphereStack, RealChromeSphereFoundWithoutAnyHint) {
  const auto root = test::shared_data("uw-psm");
  if (!root) GTEST_SKIP() << "../shared/data/uw-psm is absent";
  const auto published = published_lights(*root);
  std::vector<fs::path> files;
  for (std::size_t i = 0; i < published.size(); ++i) {
    files.push_back(*root / "chrome" / ("chrome." + std::to_string(i) + ".png"));
  }
  auto measure = [&](const StackCalibration& r, const char* label) {
    double mean = 0.0, max = 0.0;
    for (std::size_t i = 0; i < published.size(); ++i) {
      EXPECT_TRUE(r.rig.lights[i].found) << label << " " << i << ": " << r.rig.lights[i].flag;
      const double a = angle_deg(r.rig.lights[i].direction, published[i]);
      mean += a / static_cast<double>(published.size());
      max = std::max(max, a);
    }
    const Circle& c = r.rig.spheres[0].sphere;
    std::printf(
        "uw-psm chrome, %s: circle (%.2f, %.2f) r %.2f px; vs published: mean %.2f max %.2f deg\n",
        label, c.centre_px.x(), c.centre_px.y(), c.radius_px, mean, max);
    return mean;
  };
  const StackCalibration found = calibrate_sphere_stack(files, {});
  EXPECT_EQ(found.rig.usable(), static_cast<int>(published.size()));
  const double mean_found = measure(found, "no hint");
  StackCalibrationOptions masked;
  masked.rig.spheres = {circle_from_mask(read_image(*root / "chrome" / "chrome.mask.png").view())};
  const StackCalibration with_mask = calibrate_sphere_stack(files, masked);
  const double mean_masked = measure(with_mask, "mask");
  // The circle found agrees with the mask's to a pixel or two (its lower rim is black on
  // black), and the lights with the published ones as closely as with the mask.
  EXPECT_LE(
      (found.rig.spheres[0].sphere.centre_px - with_mask.rig.spheres[0].sphere.centre_px).norm(),
      kFoundVsMaskCentrePx);
  EXPECT_LE(mean_found, mean_masked + kFoundVsMaskMeanDeg);
}

}  // namespace
}  // namespace ptmkit::calib

namespace ptmkit::calib {
namespace {

// A lamp mirrored beside the light: bright in every image but not clipped, and lifted to the
// clip in one image by the light's glow. Clipped there and thicker than the light's core, it
// was taken for it (12 px off); a core's thickness counts only pixels dark in the median.
TEST(CalibSphereStack, ALampLiftedToTheClipByTheLightsGlowIsNotTheCore) {
  PTMKIT_RELEASE_BUILD_ONLY();
  PhotoImages p = render_photo("photo-chrome", kEightLights);
  const int target = 4;
  const synth::PhotoSphereTruth& s0 = p.truth.spheres[0];
  ASSERT_TRUE(s0.highlight_px[target].has_value());
  const Eigen::Vector2d hl = *s0.highlight_px[target];
  const Eigen::Vector2d lamp = hl + 12.0 * (s0.outline.centre_px - hl).normalized();
  // The lamp: 0.75 in every image; where the light is, its glow lifts the lamp to the clip.
  for (std::size_t i = 0; i < p.images.size(); ++i) {
    const float v = static_cast<int>(i) == target ? 1.0f : 0.75f;
    Image& img = p.images[i];
    for (int y = 0; y < img.height(); ++y) {
      for (int x = 0; x < img.width(); ++x) {
        if ((Eigen::Vector2d(x, y) - lamp).norm() > 6.0) continue;
        for (int c = 0; c < img.channels(); ++c) img.at(x, y, c) = v;
      }
    }
  }
  const StackCalibration r = calibrate_photo(p, 2);
  ASSERT_EQ(r.rig.spheres.size(), 2u);
  const SphereLight& l = r.rig.spheres[0].lights[target];
  ASSERT_TRUE(l.found) << l.flag;
  const double off = (l.highlight_px - hl).norm();
  std::printf("core beside a lamp lifted to the clip: %.3f px from the mirror highlight\n", off);
  EXPECT_LT(off, kLampBesideTheCorePx);
}

// A glass ball under a light near the camera's axis: its refracted hot spot is a broad clipped
// area and the surface reflection a small dot beside it or in its glow. The broad area was
// taken and the light dropped as "not a compact highlight"; on glass a compact component is
// preferred.
TEST(CalibSphereStack, GlassUnderALightAboveTheCameraKeepsItsReflection) {
  PTMKIT_RELEASE_BUILD_ONLY();
  const PhotoImages p = render_photo("photo-glass", "rings:15:3,40:3,65:2,75:2,90:1", 4);
  const StackCalibration r = calibrate_photo(p, 2);
  ASSERT_EQ(r.rig.spheres.size(), 2u);
  EXPECT_EQ(r.material, SphereMaterial::kGlass) << r.material_note;
  const std::size_t zenith = p.truth.light_dirs.size() - 1;
  ASSERT_GT(p.truth.light_dirs[zenith].z(), 0.999);
  ASSERT_TRUE(r.rig.lights[zenith].found) << r.rig.lights[zenith].flag;
  const double err = angle_deg(r.rig.lights[zenith].direction, p.truth.light_dirs[zenith]);
  double worst = 0.0;
  for (std::size_t i = 0; i < p.truth.light_dirs.size(); ++i) {
    if (!r.rig.lights[i].found) continue;
    worst = std::max(worst, angle_deg(r.rig.lights[i].direction, p.truth.light_dirs[i]));
  }
  std::printf("glass, light above the camera: %.2f deg off; worst of %zu lights %.2f deg\n", err,
              p.truth.light_dirs.size(), worst);
  EXPECT_LE(worst, kLightMaxTargetDeg);
}

// The photo-glass preset (seed 4) at `lights`, rendered at width x height.
synth::PhotoOptions glass_photo_options(const std::string& lights, int width, int height) {
  synth::PhotoOptions po = synth::photo_preset_options("photo-glass");
  po.lights = lights;
  po.seed = 4;
  synth::resize_photo(width, height, &po);
  return po;
}

// Under a light 84 degrees up a glass marble's reflection lies in the glow of its refracted hot
// spot. The glow climbs steeply toward the marble's centre, so the reflection's halo is
// symmetric only on top of that ramp (centred on plain symmetry it follows the ramp: 1.5
// degrees off); and a piece of the glow, far larger than any reflection's core, can be the
// spot that agrees better with the other marble's at the coarse scale (taken, 43 degrees off).
TEST(CalibSphereStack, AReflectionInTheGlowOfTheHotSpotIsFoundAndCentredOnTheRamp) {
  PTMKIT_RELEASE_BUILD_ONLY();
  test::ScratchDir dir;
  const synth::PhotoOptions po = glass_photo_options("rings:15:4,40:4,84:4", 1280, 720);
  const std::vector<fs::path> photos = render_photo_files(po, dir.path());
  const synth::PhotoTruth truth = synth::PhotoRenderer(po).truth();
  ASSERT_EQ(photos.size(), truth.light_dirs.size());
  StackCalibrationOptions o;
  o.rig.sphere_count = 2;
  o.rig.detection.camera.focal_px = po.focal_px;
  const StackCalibration r = calibrate_sphere_stack(photos, o);
  ASSERT_EQ(r.rig.spheres.size(), 2u);
  EXPECT_EQ(r.material, SphereMaterial::kGlass) << r.material_note;
  double sum = 0.0, worst = 0.0;
  int found = 0;
  for (std::size_t i = 0; i < truth.light_dirs.size(); ++i) {
    ASSERT_TRUE(r.rig.lights[i].found) << "light " << i << ": " << r.rig.lights[i].flag;
    const double e = angle_deg(r.rig.lights[i].direction, truth.light_dirs[i]);
    sum += e;
    worst = std::max(worst, e);
    ++found;
  }
  std::printf("glass under lights up to 84 degrees up: mean %.2f, worst %.2f deg over %d lights\n",
              sum / found, worst, found);
  EXPECT_LE(sum / found, kLightMeanTargetDeg);
  EXPECT_LE(worst, kLightMaxTargetDeg);
}

// Renders `po` to JPEG files, calibrates them as the command does with the sphere count and
// focal length, and checks every target: each circle's centre and radius, every light usable,
// the lights' mean and worst error.
void expect_photo_targets(const synth::PhotoOptions& po, const std::string& label) {
  test::ScratchDir dir;
  const std::vector<fs::path> photos = render_photo_files(po, dir.path());
  const synth::PhotoTruth truth = synth::PhotoRenderer(po).truth();
  ASSERT_EQ(photos.size(), truth.light_dirs.size());
  StackCalibrationOptions o;
  o.rig.sphere_count = static_cast<int>(po.spheres.size());
  o.rig.detection.camera.focal_px = po.focal_px;
  const StackCalibration r = calibrate_sphere_stack(photos, o);
  ASSERT_EQ(r.rig.spheres.size(), po.spheres.size());
  for (std::size_t k = 0; k < r.rig.spheres.size(); ++k) {
    const Circle& c = r.rig.spheres[k].sphere;
    const synth::SphereOutline& t = truth.spheres[k].outline;
    std::printf("%s, sphere %zu: centre %.3f px off, radius %.2f%% off\n", label.c_str(), k,
                (c.centre_px - t.centre_px).norm(),
                100.0 * std::abs(c.radius_px - t.radius_px) / t.radius_px);
    EXPECT_LE((c.centre_px - t.centre_px).norm(), kCentreTargetPx) << "sphere " << k;
    EXPECT_LE(std::abs(c.radius_px - t.radius_px), kRadiusTargetRel * t.radius_px)
        << "sphere " << k;
  }
  double sum = 0.0, worst = 0.0;
  for (std::size_t i = 0; i < truth.light_dirs.size(); ++i) {
    ASSERT_TRUE(r.rig.lights[i].found) << "light " << i << ": " << r.rig.lights[i].flag;
    const double e = angle_deg(r.rig.lights[i].direction, truth.light_dirs[i]);
    sum += e;
    worst = std::max(worst, e);
  }
  const double mean = sum / static_cast<double>(truth.light_dirs.size());
  std::printf("%s: mean %.2f, worst %.2f deg\n", label.c_str(), mean, worst);
  EXPECT_LE(mean, kLightMeanTargetDeg);
  EXPECT_LE(worst, kLightMaxTargetDeg);
}

// With few lights, four of twelve of them 80 degrees up, the glow of a glass marble's refracted
// hot spot covers its limb in a third of the images, and the median of the stack shows that
// limb as a ramp: the rim found there lies 0.7 px off on one marble, its radius 0.6% small,
// and every light it sees a few tenths of a degree off. The lower quartile of the stack keeps
// the rim sharp.
TEST(CalibSphereStack, GlassRimsUnderFewLightsAreTakenWhereTheGlowLeavesThemSharp) {
  PTMKIT_RELEASE_BUILD_ONLY();
  expect_photo_targets(glass_photo_options("rings:15:3,40:3,65:2,80:4", 1280, 720),
                       "glass under 12 lights");
}

// Black glossy spheres on cups under 18 lights, 10 of them 75-84 degrees up: in the median of
// the stack a dark cup and the spheres' shadows border part of each limb, and the edge there
// lies a few pixels outside the outline (circles 0.17-0.32 px off, lights 0.31 degrees mean).
// The maximum, where the lights lit those surroundings, shows the rim on more rays and is taken.
TEST(CalibSphereStack, TheRimIsTakenFromTheCompositeThatShowsItOnMostRays) {
  PTMKIT_RELEASE_BUILD_ONLY();
  synth::PhotoOptions po = synth::photo_preset_options("photo-dome");
  po.lights = "rings:15:4,40:4,75:6,84:4";
  po.seed = 2;
  expect_photo_targets(po, "dome under high lights");
}

// photo-chrome seed 1 in a dark room, every light of the preset (22), from its JPEG files: the
// targets. Located by the clip's edge its highlights put the lights' mean at 0.213 degrees;
// on the level set of the light's own lift, 0.162.
TEST(CalibSphereStack, PhotoChromeSeedOneMeetsTheTargets) {
  PTMKIT_RELEASE_BUILD_ONLY();
  synth::PhotoOptions po = synth::photo_preset_options("photo-chrome");
  po.seed = 1;
  expect_photo_targets(po, "photo-chrome seed 1");
}

// The light above the camera on glass, with a thicker clipped disc painted near each marble's
// rim below its reflection and joined to it by a bright (unclipped) line, so that both lie in
// one spot: the disc is taken first and reflects to below the sample plane on both marbles (as
// a piece of the hot spot's glow at the rim does at 4608 x 2592, where the light was lost).
// The next clipped component of the window is tried, and the reflection found.
TEST(CalibSphereStack, GlassTriesTheNextClippedSpotWhenTheFirstReflectsBelowThePlane) {
  PTMKIT_RELEASE_BUILD_ONLY();
  PhotoImages p = render_photo("photo-glass", "rings:15:3,40:3,65:2,75:2,90:1", 4);
  const std::size_t zenith = p.truth.light_dirs.size() - 1;
  ASSERT_GT(p.truth.light_dirs[zenith].z(), 0.999);
  Image& img = p.images[zenith];
  for (std::size_t k = 0; k < 2; ++k) {
    const synth::SphereOutline& o = p.truth.spheres[k].outline;
    ASSERT_TRUE(p.truth.spheres[k].highlight_px[zenith].has_value());
    const Eigen::Vector2d dot = *p.truth.spheres[k].highlight_px[zenith];
    const Eigen::Vector2d disc = o.centre_px + Eigen::Vector2d(0.0, 0.9 * o.radius_px);
    paint_clipped_disc(&img, disc, 2.5);
    for (double t = 0.0; t <= 1.0; t += 0.02) {
      const Eigen::Vector2d q = dot + t * (disc - dot);
      const int x = static_cast<int>(std::lround(q.x()));
      const int y = static_cast<int>(std::lround(q.y()));
      for (int c = 0; c < img.channels(); ++c) img.at(x, y, c) = std::max(img.at(x, y, c), 0.9f);
    }
  }
  const StackCalibration r = calibrate_photo(p, 2);
  ASSERT_EQ(r.rig.spheres.size(), 2u);
  EXPECT_EQ(r.material, SphereMaterial::kGlass) << r.material_note;
  const RigLight& l = r.rig.lights[zenith];
  ASSERT_TRUE(l.found) << l.flag;
  const double err = angle_deg(l.direction, p.truth.light_dirs[zenith]);
  std::printf("glass, light above the camera past a painted disc: %.2f deg off (%s)\n", err,
              l.flag.c_str());
  EXPECT_LE(err, kLightMaxTargetDeg);
  EXPECT_TRUE(l.outlier) << "taken past another clipped spot: doubtful";
}

// A photographic render calibrated as at photo size: analysed at half its size (scale 2), so
// that the photo-size composites are the mean and the maximum, and every circle checked against
// the targets (label: what the printed line calls it).
void check_circles_at_scale_2(const PhotoImages& p, int spheres, const char* label) {
  StackCalibrationOptions o;
  o.rig.sphere_count = spheres;
  o.rig.detection.camera.focal_px = p.options.focal_px;
  o.search.analysis_max_side_px = 320;
  const StackCalibration r = calibrate_sphere_stack(p.images, p.names, o);
  EXPECT_EQ(r.analysis_scale, 2);
  ASSERT_EQ(r.rig.spheres.size(), static_cast<std::size_t>(spheres));
  for (std::size_t k = 0; k < r.rig.spheres.size(); ++k) {
    const Circle& c = r.rig.spheres[k].sphere;
    const synth::SphereOutline& t = p.truth.spheres[k].outline;
    const double off = (c.centre_px - t.centre_px).norm();
    const double rel = std::abs(c.radius_px - t.radius_px) / t.radius_px;
    std::printf("%s at scale 2, sphere %zu: centre off %.3f px, radius off %.2f%%\n", label, k, off,
                100.0 * rel);
    EXPECT_LE(off, kCentreTargetPx) << label << " sphere " << k;
    EXPECT_LE(rel, kRadiusTargetRel) << label << " sphere " << k;
  }
}

// At photo sizes (scale > 1) the photo-size composites, mean and maximum, hold what moves: a
// glass ball's caustics and hot spots beside its limb pulled the rim (at 1600 x 900, 1.9 and
// 1.1 px off). The rim is checked against the median of the block means at the analysis size.
TEST(CalibSphereStack, GlassRimsAtPhotoSizeAreCheckedAgainstTheBlockMedian) {
  PTMKIT_RELEASE_BUILD_ONLY();
  check_circles_at_scale_2(render_photo("photo-glass", "rings:15:4,35:4,55:4,75:2", 4), 2, "glass");
}

// The block median's circle replaces the photo-size one only where it is clearly better
// supported: a large black sphere's limb fades into a dark room the same way in both, and the
// photo-size circle keeps its resolution.
TEST(CalibSphereStack, ALargeSphereAtPhotoSizeKeepsItsPhotoSizeRim) {
  check_circles_at_scale_2(render_photo("photo-large-sphere", "", 2), 1, "large sphere");
}

// A pinhole camera sees a sphere off its axis as an ellipse, stretched away from the image
// centre (2% for photo-dome's spheres, 12 degrees off the axis): a circle chosen by the rim
// points within a pixel of it followed one side (2.5-2.7 px off at 2560 x 1440). With the focal
// length the outline is fitted as the tangent cone it is. At 1280 x 720 (scale 2), where the
// circle was 0.26-0.29 px off and its radius 0.12-0.15% short:
TEST(CalibSphereStack, AnOffAxisSphereIsFittedAsThePinholeSeesIt) {
  PTMKIT_RELEASE_BUILD_ONLY();
  const PhotoImages p = render_photo("photo-dome", "rings:15:4,40:4", 1, 0, 1280, 720);
  StackCalibrationOptions o;
  o.rig.sphere_count = 2;
  o.rig.detection.camera.focal_px = p.options.focal_px;
  o.search.analysis_max_side_px = 640;
  const StackCalibration r = calibrate_sphere_stack(p.images, p.names, o);
  EXPECT_EQ(r.analysis_scale, 2);
  ASSERT_EQ(r.rig.spheres.size(), 2u);
  for (std::size_t k = 0; k < 2; ++k) {
    const Circle& c = r.rig.spheres[k].sphere;
    const synth::SphereOutline& t = p.truth.spheres[k].outline;
    const double off = (c.centre_px - t.centre_px).norm();
    std::printf("off-axis sphere %zu at 1280 x 720: centre off %.3f px, radius off %.2f%%\n", k,
                off, 100.0 * (c.radius_px / t.radius_px - 1.0));
    EXPECT_LE(off, 0.1) << k;
    EXPECT_LE(std::abs(c.radius_px - t.radius_px) / t.radius_px, 0.001) << k;
  }
}

// A large sphere's rim profiles are sampled every pixel at most: at r / 200 (3.6 px on a sphere
// of radius 720 px, at 2560 x 1440) a parabola through samples further apart than the blurred
// edge is wide misplaced the rim, and the circle was 1.1 px off here (0.5-1.0 px on JPEG
// captures of 12 lights).
TEST(CalibSphereStack, ALargeSphereAtTwentyFiveHundredPixelsIsFoundToAFractionOfAPixel) {
  PTMKIT_RELEASE_BUILD_ONLY();
  const PhotoImages p = render_photo("photo-large-sphere", "rings:45:3", 2, 0, 2560, 1440);
  StackCalibrationOptions o;
  o.rig.detection.camera.focal_px = p.options.focal_px;
  const StackCalibration r = calibrate_sphere_stack(p.images, p.names, o);
  ASSERT_EQ(r.rig.spheres.size(), 1u);
  const Circle& c = r.rig.spheres[0].sphere;
  const synth::SphereOutline& t = p.truth.spheres[0].outline;
  const double off = (c.centre_px - t.centre_px).norm();
  std::printf("large sphere at 2560 x 1440: centre off %.3f px, radius off %.3f%%\n", off,
              100.0 * (c.radius_px / t.radius_px - 1.0));
  EXPECT_LE(off, 0.35);
  EXPECT_LE(std::abs(c.radius_px - t.radius_px) / t.radius_px, 0.001);
}

// Cameras record the focal length in EXIF; `ptmkit synth` writes it as they do. Without a
// focal length given, `calibrate sphere` takes the photographs' (the perspective model: two
// spheres off the optical axis see each light from directions a few degrees apart), says so,
// and reports it; --no-exif-focal and --focal-px 0 keep the orthographic camera.
// Glass marbles under lights mostly near the camera's axis (4 at 20 degrees, 10 at 75-84), at
// 960 x 540: the glow of the hot spots hides the marbles, and the best pair of candidates is a
// circle around the object and a smaller one beside a marble. Their highlights disagree about
// 12 of 14 lights (as distant lights and as near ones): the command refuses them, lists the
// candidates and draws them, and writes no light file; --allow-disagreement writes the lights,
// flagged.
TEST(CalibSphereStack, CommandRefusesSpheresThatDisagreeAboutMostLights) {
  PTMKIT_RELEASE_BUILD_ONLY();
  test::ScratchDir dir;
  const synth::PhotoOptions po = glass_photo_options("rings:20:4,75:6,84:4", 960, 540);
  const std::vector<fs::path> photos = render_photo_files(po, dir.path());
  std::vector<std::string> run{"calibrate", "sphere"};
  for (const fs::path& f : photos) run.push_back(f.string());
  run.insert(run.end(), {"--spheres", "2", "-o", (dir / "l.lp").string()});
  const auto r = test::run_ptmkit(run);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("most likely not the capture's spheres"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("--allow-disagreement"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir / "l.lp"));
  EXPECT_TRUE(fs::exists(dir / "l.candidates.png"));
  run.push_back("--allow-disagreement");
  const auto a = test::run_ptmkit(run);
  ASSERT_EQ(a.exit_code, 0) << a.err;
  EXPECT_NE(a.out.find("outliers"), std::string::npos) << a.out;
  EXPECT_TRUE(fs::exists(dir / "l.lp"));
}

TEST(CalibSphereStack, CommandTakesTheFocalLengthFromThePhotographsExif) {
  PTMKIT_RELEASE_BUILD_ONLY();
  test::ScratchDir dir;
  const auto s = test::run_ptmkit({"synth", "--preset", "photo-dome", "--lights", kEightLights,
                                   "--out", (dir / "cap").string()});
  ASSERT_EQ(s.exit_code, 0) << s.err;
  std::vector<std::string> photos;
  for (const auto& f : test::list_files(dir / "cap")) {
    if (f.rfind("image_", 0) == 0) photos.push_back((dir / "cap" / f).string());
  }
  ASSERT_EQ(photos.size(), 8u);
  const auto calibrate = [&](const std::string& name, std::vector<std::string> extra) {
    std::vector<std::string> args{"calibrate", "sphere"};
    args.insert(args.end(), photos.begin(), photos.end());
    args.insert(args.end(), {"--spheres", "2", "-o", (dir / (name + ".lp")).string(), "--report",
                             (dir / (name + ".json")).string()});
    args.insert(args.end(), extra.begin(), extra.end());
    const auto r = test::run_ptmkit(args);
    EXPECT_EQ(r.exit_code, 0) << r.err;
    std::ifstream in(dir / (name + ".json"));
    return std::make_pair(r.out, nlohmann::json::parse(in));
  };
  const auto [exif_out, exif] = calibrate("exif", {});
  EXPECT_NE(exif_out.find("camera focal length 1280.0 px, from the photographs' EXIF"),
            std::string::npos)
      << exif_out;
  EXPECT_NEAR(exif.at("focal_px").get<double>(), 1280.0, 0.01);
  EXPECT_NE(exif.at("focal_source").get<std::string>().find("FocalLength 47 mm"),
            std::string::npos);
  const auto [given_out, given] = calibrate("given", {"--focal-px", "1280"});
  EXPECT_NE(given_out.find("from --focal-px"), std::string::npos) << given_out;
  const LightSet a = read_lp(dir / "exif.lp"), b = read_lp(dir / "given.lp");
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    EXPECT_LT(angle_deg(a.lights[i].direction, b.lights[i].direction), 0.01) << i;
  }
  for (const auto& extra :
       {std::vector<std::string>{"--no-exif-focal"}, std::vector<std::string>{"--focal-px", "0"}}) {
    const auto [out, report] = calibrate("ortho", extra);
    EXPECT_NE(out.find("orthographic"), std::string::npos) << out;
    EXPECT_EQ(report.at("focal_px").get<double>(), 0.0);
  }
}

// The photographs' EXIF focal length is used only when every one gives the same.
TEST(CalibSphereStack, ExifFocalLengthsThatDifferAreNotUsed) {
  test::ScratchDir dir;
  Image img(32, 24, 3);
  ImageWriteOptions o;
  o.exif_camera = ImageWriteOptions::ExifCamera{35.0, 23.5};
  write_image(dir / "a.jpg", img.view(), o);
  write_image(dir / "b.jpg", img.view(), o);
  const PhotoFocal same = focal_from_exif({dir / "a.jpg", dir / "b.jpg"});
  EXPECT_NEAR(same.focal_px, 35.0 / 23.5 * 32, 1e-3);
  o.exif_camera->focal_mm = 50.0;
  write_image(dir / "c.jpg", img.view(), o);
  const PhotoFocal zoomed = focal_from_exif({dir / "a.jpg", dir / "c.jpg"});
  EXPECT_EQ(zoomed.focal_px, 0.0);
  EXPECT_NE(zoomed.note.find("differ"), std::string::npos) << zoomed.note;
  write_image(dir / "d.jpg", img.view());
  const PhotoFocal partial = focal_from_exif({dir / "a.jpg", dir / "d.jpg"});
  EXPECT_EQ(partial.focal_px, 0.0);
  EXPECT_NE(partial.note.find("1 of 2"), std::string::npos) << partial.note;
  EXPECT_THROW((void)focal_from_exif({dir / "missing.jpg"}), Error);
}

TEST(CalibSphereStack, CommandCalibratesTheRealChromeSphereWithoutHints) {
  const auto root = test::shared_data("uw-psm");
  if (!root) GTEST_SKIP() << "../shared/data/uw-psm is absent";
  test::ScratchDir dir;
  std::vector<std::string> args{"calibrate", "sphere"};
  for (int i = 0; i < 12; ++i) {
    args.push_back((*root / "chrome" / ("chrome." + std::to_string(i) + ".png")).string());
  }
  args.insert(args.end(),
              {"-o", (dir / "chrome.lp").string(), "--report", (dir / "chrome.json").string(),
               "--overlays", (dir / "ov").string(), "--overlay-max-side", "256"});
  const auto r = test::run_ptmkit(args);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("found, score"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("12 of 12 lights usable"), std::string::npos) << r.out;
  EXPECT_EQ(read_lp(dir / "chrome.lp").size(), 12u);
  const auto overlays = test::list_files(dir / "ov");
  ASSERT_EQ(overlays.size(), 12u);
  const ImageInfo info = probe_image(dir / "ov" / overlays.front());
  EXPECT_LE(std::max(info.width, info.height), 256);
  std::ifstream report_file(dir / "chrome.json");
  const auto report = nlohmann::json::parse(report_file);
  EXPECT_EQ(report.at("material"), "mirror");

  // The material given is reported as given; an unknown one is refused before any output.
  std::vector<std::string> given(args.begin(), args.begin() + 14);
  given.insert(given.end(), {"-o", (dir / "given.lp").string(), "--report",
                             (dir / "given.json").string(), "--sphere-material", "mirror"});
  ASSERT_EQ(test::run_ptmkit(given).exit_code, 0);
  std::ifstream given_file(dir / "given.json");
  const auto given_report = nlohmann::json::parse(given_file);
  EXPECT_EQ(given_report.at("material"), "mirror");
  EXPECT_NE(given_report.at("material_note").get<std::string>().find("given"), std::string::npos);
  std::vector<std::string> bad(args.begin(), args.begin() + 14);
  bad.insert(bad.end(), {"-o", (dir / "bad.lp").string(), "--sphere-material", "crystal"});
  const auto b = test::run_ptmkit(bad);
  EXPECT_NE(b.exit_code, 0);
  EXPECT_NE(b.err.find("--sphere-material"), std::string::npos) << b.err;
  EXPECT_FALSE(fs::exists(dir / "bad.lp"));
}

}  // namespace
}  // namespace ptmkit::calib
