// Light directions from a specular sphere: rendered spheres with known lights, flags for
// unusable images, and the real chrome-sphere photographs of uw-psm (skipped where absent).
#include <cmath>
#include <cstdio>
#include <fstream>
#include <numbers>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "ptmkit/calib/dome.h"
#include "ptmkit/calib/sphere.h"
#include "ptmkit/calib/sphere_refine.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/core/light_set.h"
#include "ptmkit/synth/rig.h"
#include "test_util.h"
#include "tolerances.h"

namespace fs = std::filesystem;

namespace ptmkit::calib {
namespace {

// Mean light error, orthographic noise-free renders: the target of docs/CALIBRATION.md's
// sphere accuracy table (measured 0.029 degrees with the circle given, 0.030 found).
constexpr double kOrthographicTargetDeg = 0.1;
// Mean light error, off-axis pinhole renders with noise 2 grey levels: the target of
// docs/CALIBRATION.md's sphere accuracy table (measured 0.024 degrees).
constexpr double kPerspectiveTargetDeg = 0.5;
// The circle found on a noise-free render: measured 0.009 px off in centre and radius.
constexpr double kFoundCircleTolPx = 0.1;
// The orthographic model on the off-axis render is measurably worse than the perspective one
// (measured 9.1 against 0.024 degrees): by more than this factor.
constexpr double kOrthographicWorseFactor = 2.0;
// A sphere cut by the frame and on a stand, noise 1 grey level: circle measured 0.02 px off.
constexpr double kCroppedCircleTolPx = 1.0;
// Its worst usable light: measured 0.225 degrees (docs/CALIBRATION.md: 0.23).
constexpr double kCroppedWorstLightDeg = 0.5;
// uw-psm's published lights came from a simpler estimator (its README: expect differences of a
// few degrees); one pixel of highlight is about a degree here and every highlight is a
// saturated, flared blob of about 10 px, so locators differ by a few pixels: measured 3.10
// degrees mean (docs/CALIBRATION.md). A broken estimator (a flipped axis, a wrong circle) is
// tens of degrees off.
constexpr double kPublishedChromeAgreementDeg = 5.0;
// Lights through the command (8-bit PNG renders): measured worst 0.043 degrees.
constexpr double kCommandLightTolDeg = 0.3;

double angle_deg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::acos(std::clamp(a.normalized().dot(b.normalized()), -1.0, 1.0)) * 180.0 /
         std::numbers::pi;
}

// Lights from 30 degrees up (lower ones put the highlight near the rim, where 1 px of error is
// worth several degrees: docs/CALIBRATION.md).
std::vector<Eigen::Vector3d> test_lights() {
  return layout_directions("rings:30:8:10,50:6:20,70:4:30,90:1");
}

struct Errors {
  double mean = 0.0, max = 0.0;
};

Errors errors(const SphereReport& report, const std::vector<Eigen::Vector3d>& truth) {
  Errors e;
  for (std::size_t i = 0; i < truth.size(); ++i) {
    EXPECT_TRUE(report.lights[i].found) << report.lights[i].flag;
    const double a = angle_deg(report.lights[i].direction, truth[i]);
    e.mean += a / static_cast<double>(truth.size());
    e.max = std::max(e.max, a);
  }
  return e;
}

TEST(CalibSphere, OrthographicNoiseFreeWithinATenthOfADegree) {
  const auto lights = test_lights();
  synth::SphereRigOptions rig;  // 400 x 400, radius 160 px, orthographic
  std::vector<Image> images;
  std::vector<fs::path> names;
  for (std::size_t i = 0; i < lights.size(); ++i) {
    rig.light_dir = lights[i];
    images.push_back(synth::render_sphere_rig(rig));
    names.emplace_back("img" + std::to_string(i) + ".png");
  }
  SphereOptions given;
  given.sphere = Circle{rig.centre_px, rig.radius_px, {}};
  const Errors known = errors(calibrate_sphere(images, names, given), lights);
  const SphereReport found = calibrate_sphere(images, names, {});
  EXPECT_TRUE(found.sphere_detected);
  EXPECT_NEAR((found.sphere.centre_px - rig.centre_px).norm(), 0.0, kFoundCircleTolPx);
  EXPECT_NEAR(found.sphere.radius_px, rig.radius_px, kFoundCircleTolPx);
  const Errors detected = errors(found, lights);
  std::printf(
      "orthographic, r = 160 px, noise-free: mean %.4f max %.4f deg (circle given); "
      "mean %.4f max %.4f deg (circle found)\n",
      known.mean, known.max, detected.mean, detected.max);
  EXPECT_LE(known.mean, kOrthographicTargetDeg);
  EXPECT_LE(detected.mean, kOrthographicTargetDeg);
  // Refined as a rig (one sphere, distant lights: the circle from its outline, each light
  // from its highlight); a clean render has no outliers.
  RigOptions rig_options;
  const RigReport refined = calibrate_rig(images, names, rig_options);
  Errors e_refined;
  for (std::size_t i = 0; i < lights.size(); ++i) {
    const double a = angle_deg(refined.lights[i].direction, lights[i]);
    e_refined.mean += a / static_cast<double>(lights.size());
    e_refined.max = std::max(e_refined.max, a);
  }
  std::printf("  refined (circle found): mean %.4f max %.4f deg, %d outliers\n", e_refined.mean,
              e_refined.max, refined.outliers());
  EXPECT_EQ(refined.outliers(), 0);
  EXPECT_LE(e_refined.mean, kOrthographicTargetDeg);
}

TEST(CalibSphere, PerspectiveOffAxisWithNoiseWithinHalfADegree) {
  PTMKIT_RELEASE_BUILD_ONLY();
  // A 1200 x 800 image, f = 1400 px (a normal lens), the sphere 7 radii away and well
  // off-axis: its image centre 300 px right and 150 px up of the principal point, radius
  // about 200 px, wholly in view.
  const auto lights = test_lights();
  synth::SphereRigOptions rig;
  rig.width = 1200;
  rig.height = 800;
  rig.focal_px = 1400.0;
  rig.principal_px = {599.5, 399.5};
  rig.centre_cam = {1.5, -0.75, 7.0};
  rig.noise_grey = 2.0;
  rig.supersample = 3;
  std::vector<Image> images;
  std::vector<fs::path> names;
  for (std::size_t i = 0; i < lights.size(); ++i) {
    rig.light_dir = lights[i];
    rig.seed = i + 1;
    images.push_back(synth::render_sphere_rig(rig));
    names.emplace_back("img" + std::to_string(i) + ".png");
  }
  SphereOptions persp;
  persp.camera.focal_px = rig.focal_px;
  persp.camera.principal_px = rig.principal_px;
  const SphereReport with_model = calibrate_sphere(images, names, persp);
  const Errors p = errors(with_model, lights);
  const Errors o = errors(calibrate_sphere(images, names, {}), lights);
  std::printf(
      "pinhole f = 1400 px, off-axis, noise 2 grey: perspective model mean %.3f max %.3f "
      "deg; orthographic model mean %.3f max %.3f deg\n",
      p.mean, p.max, o.mean, o.max);
  EXPECT_LE(p.mean, kPerspectiveTargetDeg);
  EXPECT_GT(o.mean, kOrthographicWorseFactor * p.mean);
  RigOptions rig_options;
  rig_options.detection = persp;
  const RigReport refined = calibrate_rig(images, names, rig_options);
  Errors e_refined;
  for (std::size_t i = 0; i < lights.size(); ++i) {
    const double a = angle_deg(refined.lights[i].direction, lights[i]);
    e_refined.mean += a / static_cast<double>(lights.size());
    e_refined.max = std::max(e_refined.max, a);
  }
  std::printf("  refined: mean %.3f max %.3f deg, %d outliers, outline rms %.3f px\n",
              e_refined.mean, e_refined.max, refined.outliers(), refined.outline_rms_px);
  EXPECT_EQ(refined.outliers(), 0);
  EXPECT_LE(e_refined.mean, kPerspectiveTargetDeg);
}

// A sphere partly outside the frame and held by a stand (a grey rod from below touching its
// outline): found automatically, and every light either right or flagged, never wrong.
TEST(CalibSphere, CroppedSphereOnAStandIsFoundAndItsLightsAreRightOrFlagged) {
  const auto lights = test_lights();
  synth::SphereRigOptions rig;
  rig.width = 360;
  rig.height = 320;
  rig.centre_px = {95.3, 150.6};  // 15 px of the left side cut off by the frame
  rig.radius_px = 110.0;
  rig.noise_grey = 1.0;
  std::vector<Image> images;
  std::vector<fs::path> names;
  for (std::size_t i = 0; i < lights.size(); ++i) {
    rig.light_dir = lights[i];
    rig.seed = i + 1;
    Image im = synth::render_sphere_rig(rig);
    for (int y = 0; y < im.height(); ++y) {  // the stand
      for (int x = 0; x < im.width(); ++x) {
        const double dx = x - rig.centre_px.x(), dy = y - rig.centre_px.y();
        if (std::abs(dx) <= 12.0 && dy > 0.0 && std::hypot(dx, dy) > rig.radius_px) {
          im.at(x, y, 0) = 0.15f;
        }
      }
    }
    images.push_back(std::move(im));
    names.emplace_back("crop" + std::to_string(i) + ".png");
  }
  const SphereReport found = calibrate_sphere(images, names, {});
  std::printf("cropped sphere on a stand: found at (%.2f, %.2f) r %.2f (true %.2f, %.2f, %.2f)\n",
              found.sphere.centre_px.x(), found.sphere.centre_px.y(), found.sphere.radius_px,
              rig.centre_px.x(), rig.centre_px.y(), rig.radius_px);
  EXPECT_LT((found.sphere.centre_px - rig.centre_px).norm(), kCroppedCircleTolPx);
  EXPECT_NEAR(found.sphere.radius_px, rig.radius_px, kCroppedCircleTolPx);
  int usable = 0;
  double worst = 0.0;
  for (std::size_t i = 0; i < lights.size(); ++i) {
    if (!found.lights[i].found) continue;
    ++usable;
    worst = std::max(worst, angle_deg(found.lights[i].direction, lights[i]));
  }
  std::printf("  %d of %zu lights usable, worst %.3f deg\n", usable, lights.size(), worst);
  EXPECT_GE(usable, static_cast<int>(lights.size()) - 2);
  EXPECT_LT(worst, kCroppedWorstLightDeg);
}

TEST(CalibSphere, UnusableImagesAreFlaggedNotGuessed) {
  synth::SphereRigOptions rig;
  rig.light_dir = {0.2, 0.3, 0.9};
  std::vector<Image> images{synth::render_sphere_rig(rig)};
  rig.highlight = 0.0;  // no highlight at all
  images.push_back(synth::render_sphere_rig(rig));
  rig.highlight = 0.9;
  rig.light_radius_deg = 40.0;  // a huge bright patch, not a compact highlight
  images.push_back(synth::render_sphere_rig(rig));
  SphereOptions o;
  o.sphere = Circle{rig.centre_px, rig.radius_px, {}};
  const SphereReport r = calibrate_sphere(images, {"a.png", "b.png", "c.png"}, o);
  EXPECT_TRUE(r.lights[0].found);
  EXPECT_FALSE(r.lights[1].found);
  EXPECT_THAT(r.lights[1].flag, ::testing::HasSubstr("no highlight"));
  EXPECT_FALSE(r.lights[2].found);
  EXPECT_THAT(r.lights[2].flag, ::testing::HasSubstr("not a compact highlight"));
  EXPECT_EQ(sphere_light_set(r).size(), 1u);
  // Nothing circular: an error that says what to try.
  try {
    (void)find_sphere({Image(64, 64, 1, ColourSpace::kLinear, 0.5f)});
    FAIL();
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), ::testing::HasSubstr("--sphere"));
  }
}

// uw-psm's chrome sphere: 12 photographs, circle from its mask. Its published lights.txt came
// from a simpler estimator, so agreement within a few degrees is what to expect.
TEST(CalibSphere, RealChromeSphereAgreesWithThePublishedLights) {
  const auto root = test::shared_data("uw-psm");
  if (!root) GTEST_SKIP() << "../shared/data/uw-psm is absent";
  std::ifstream lf(*root / "lights.txt");
  int n = 0;
  lf >> n;
  std::vector<Eigen::Vector3d> published(static_cast<std::size_t>(n));
  for (auto& v : published) lf >> v.x() >> v.y() >> v.z();
  std::vector<Image> images;
  std::vector<fs::path> names;
  for (int i = 0; i < n; ++i) {
    names.push_back(*root / "chrome" / ("chrome." + std::to_string(i) + ".png"));
    images.push_back(read_image(names.back()));
  }
  SphereOptions o;
  o.sphere = circle_from_mask(read_image(*root / "chrome" / "chrome.mask.png").view());
  const SphereReport r = calibrate_sphere(images, names, o);
  const Errors e = errors(r, published);
  std::printf(
      "uw-psm chrome: circle (%.2f, %.2f) r %.2f px; vs published lights.txt: mean %.2f "
      "max %.2f deg\n",
      r.sphere.centre_px.x(), r.sphere.centre_px.y(), r.sphere.radius_px, e.mean, e.max);
  EXPECT_EQ(r.usable(), n);
  EXPECT_LE(e.mean, kPublishedChromeAgreementDeg);
  RigOptions rig_options;
  rig_options.spheres = {o.sphere.value()};
  const RigReport refined = calibrate_rig(images, names, rig_options);
  Errors e_refined;
  for (std::size_t i = 0; i < published.size(); ++i) {
    const double a = angle_deg(refined.lights[i].direction, published[i]);
    e_refined.mean += a / static_cast<double>(published.size());
    e_refined.max = std::max(e_refined.max, a);
  }
  std::printf("  refined: mean %.2f max %.2f deg; %d outliers\n", e_refined.mean, e_refined.max,
              refined.outliers());
  for (const RigLight& l : refined.lights) {
    if (l.outlier) std::printf("    %s: %s\n", l.image.filename().string().c_str(), l.flag.c_str());
  }
  EXPECT_LE(e_refined.mean, kPublishedChromeAgreementDeg);
}

TEST(CalibSphere, CommandWritesUsableLightsAndFlagsTheRest) {
  test::ScratchDir dir;
  const auto lights = layout_directions("rings:45:4:10,80:1");
  synth::SphereRigOptions rig;
  std::vector<std::string> args{"calibrate", "sphere"};
  for (std::size_t i = 0; i < lights.size(); ++i) {
    rig.light_dir = lights[i];
    char name[32];
    std::snprintf(name, sizeof(name), "s%zu.png", i);
    const fs::path p = dir / name;
    write_image(p, synth::render_sphere_rig(rig).view());
    args.push_back(p.string());
  }
  rig.highlight = 0.0;
  write_image(dir / "dark.png", synth::render_sphere_rig(rig).view());
  args.push_back((dir / "dark.png").string());
  auto ok_args = args;
  ok_args.insert(
      ok_args.end(),
      {"-o", (dir / "lights.lp").string(), "--report", (dir / "report.json").string(), "--overlays",
       (dir / "overlays").string(), "--plot", (dir / "polar.png").string()});
  const auto r = test::run_ptmkit(ok_args);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_THAT(r.out, ::testing::HasSubstr("5 of 6 lights usable"));
  EXPECT_THAT(r.out, ::testing::HasSubstr("flagged dark.png"));
  const LightSet lp = read_lp(dir / "lights.lp");
  ASSERT_EQ(lp.size(), lights.size());
  for (std::size_t i = 0; i < lights.size(); ++i) {
    EXPECT_LT(angle_deg(lp.lights[i].direction, lights[i]), kCommandLightTolDeg);
  }
  EXPECT_TRUE(fs::exists(dir / "report.json"));
  EXPECT_EQ(test::list_files(dir / "overlays").size(), lights.size() + 1);
  EXPECT_EQ(probe_image(dir / "polar.png").width, 600);
  // Dropping a light by index leaves it out.
  auto drop_args = args;
  drop_args.insert(drop_args.end(), {"--drop", "1,2", "-o", (dir / "dropped.lp").string()});
  const auto d = test::run_ptmkit(drop_args);
  ASSERT_EQ(d.exit_code, 0) << d.err;
  EXPECT_EQ(read_lp(dir / "dropped.lp").size(), lights.size() - 2);
  auto bad_drop = args;
  bad_drop.insert(bad_drop.end(), {"--drop", "17", "-o", (dir / "x.lp").string()});
  EXPECT_EQ(test::run_ptmkit(bad_drop).exit_code, 1);
  EXPECT_FALSE(fs::exists(dir / "x.lp"));
  // Only dark images: nothing usable, an error, and no light file.
  const auto bad = test::run_ptmkit({"calibrate", "sphere", (dir / "dark.png").string(), "--sphere",
                                     "200,200,160", "-o", (dir / "none.lp").string()});
  EXPECT_EQ(bad.exit_code, 1);
  EXPECT_FALSE(fs::exists(dir / "none.lp"));
}

}  // namespace
}  // namespace ptmkit::calib
