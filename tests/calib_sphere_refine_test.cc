// The sphere rig refined as a whole: two spheres of known size triangulate near lights on a
// dome; a highlight that disagrees (a planted reflection, two spheres that see different
// lights) is flagged, and dropped only when asked.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <numbers>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "ptmkit/calib/camera.h"
#include "ptmkit/calib/dome.h"
#include "ptmkit/calib/sphere.h"
#include "ptmkit/calib/sphere_refine.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/core/light_set.h"
#include "ptmkit/core/plane.h"
#include "ptmkit/synth/rig.h"
#include "test_util.h"

namespace fs = std::filesystem;

namespace ptmkit::calib {
namespace {

double angle_deg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::acos(std::clamp(a.normalized().dot(b.normalized()), -1.0, 1.0)) * 180.0 /
         std::numbers::pi;
}

// The scene: the camera 600 mm above the sample plane looking straight down; two spheres of
// 25 mm radius resting on the plane 180 mm apart; a dome of radius 500 mm centred on the
// plane's centre. Light frame -> camera frame: (x, y, z) -> (x, -y, 600 - z).
constexpr double kDistance = 600.0, kDome = 500.0, kSphere = 25.0;

// Near-light positions within 1% of the dome radius: the requirement (docs/TARGETS.md).
// Measured worst 0.29% noise-free, 0.62% with noise 2 grey levels.
constexpr double kNearLightTargetPercent = 1.0;
// The spheres' centres in the camera frame (600 mm away): measured 0.18 mm off.
constexpr double kSphereCentreTolMm = 1.0;
// A good near light's residual (4 measurements, 3 unknowns): measured worst 0.016 px.
constexpr double kGoodResidualPx = 0.5;
// A light the spheres disagree about: confidence measured 0.005 (good lights 0.8 or more).
constexpr double kDisagreeingConfidence = 0.1;
// Mean error of the other lights, two spheres, distant lights, noise 1 grey: measured 0.012
// degrees.
constexpr double kTwoSphereMeanTolDeg = 0.2;
// Lights of a single orthographic sphere, noise 1 grey level: measured worst 0.033
// degrees.
constexpr double kSingleSphereLightTolDeg = 0.3;
// Confidence of a clean light: measured 0.81 or more.
constexpr double kCleanConfidence = 0.5;
// Confidence of the light with a planted second candidate: measured 0.06.
constexpr double kAmbiguousConfidence = 0.2;
// One sphere with distant lights: two unknowns, two measurements, so the highlight residual is
// zero by construction (measured 0); this allows for rounding only.
constexpr double kExactResidualPx = 1e-3;

Eigen::Vector3d camera_from_light(const Eigen::Vector3d& p) {
  return {p.x(), -p.y(), kDistance - p.z()};
}

synth::SphereRigOptions two_sphere_rig() {
  synth::SphereRigOptions rig;
  rig.width = 640;
  rig.height = 400;
  rig.focal_px = 1500.0;  // spheres of about 65 px radius
  rig.principal_px = {319.5, 199.5};
  rig.spheres = {{camera_from_light({-90.0, 0.0, kSphere}), kSphere},
                 {camera_from_light({90.0, 0.0, kSphere}), kSphere}};
  rig.supersample = 3;
  // A light of 2 degrees (17 mm across at 500 mm): on spheres this small a 0.5 degree light
  // leaves a highlight of a fraction of a pixel, too dim to find.
  rig.light_radius_deg = 2.0;
  // A camera integrates each pixel exactly: sample the highlight finely (3 x 3 sub-samples
  // alone move it by up to a tenth of a pixel, 1% of the dome radius here).
  rig.highlight_supersample = 12;
  return rig;
}

SamplePlane plane_of_the_scene() {
  SamplePlane plane;
  plane.width_px = 640;
  plane.height_px = 400;
  PlanePose pose;
  pose.camera_from_plane = Eigen::Vector3d(1.0, -1.0, -1.0).asDiagonal();
  pose.plane_origin_in_camera_mm = {0.0, 0.0, kDistance};
  plane.pose = pose;
  return plane;
}

struct Stats {
  double mean = 0.0, max = 0.0;
};

// Near lights on the dome: triangulated positions against the truth, in % of the radius.
// The rig under 17 near lights on the dome (directions from the dome's centre in `dirs`).
struct DomeCapture {
  std::vector<Eigen::Vector3d> dirs;
  synth::SphereRigOptions rig;
  std::vector<Image> images;
  std::vector<fs::path> names;
};
DomeCapture render_dome(double noise_grey, double light_radius_deg = 2.0) {
  DomeCapture d;
  d.dirs = layout_directions("rings:30:6:15,50:6,70:4:45,90:1");
  d.rig = two_sphere_rig();
  d.rig.noise_grey = noise_grey;
  d.rig.light_radius_deg = light_radius_deg;
  synth::SphereRigOptions rig = d.rig;
  for (std::size_t i = 0; i < d.dirs.size(); ++i) {
    rig.light_position_mm = camera_from_light(kDome * d.dirs[i]);
    rig.seed = i + 1;
    d.images.push_back(synth::render_sphere_rig(rig));
    d.names.emplace_back("img" + std::to_string(i) + ".png");
  }
  return d;
}

Stats triangulate(double noise_grey, RigReport* out = nullptr, bool refine = true,
                  double light_radius_deg = 2.0) {
  const DomeCapture d = render_dome(noise_grey, light_radius_deg);
  const auto& dirs = d.dirs;
  const auto& rig = d.rig;
  const auto& images = d.images;
  const auto& names = d.names;
  RigOptions o;
  o.sphere_count = 2;  // found
  o.detection.camera.focal_px = rig.focal_px;
  o.detection.camera.principal_px = rig.principal_px;
  o.sphere_radius_mm = kSphere;
  o.plane = plane_of_the_scene();
  o.refine = refine;
  const RigReport r = calibrate_rig(images, names, o);
  EXPECT_EQ(r.model, "pinhole near");
  EXPECT_EQ(r.usable(), static_cast<int>(dirs.size()));
  EXPECT_EQ(r.outliers(), 0);
  Stats s;
  for (std::size_t i = 0; i < dirs.size(); ++i) {
    const RigLight& l = r.lights[i];
    EXPECT_TRUE(l.found) << l.flag;
    if (!l.position_mm) {
      ADD_FAILURE() << "light " << i << " has no position";
      continue;
    }
    EXPECT_FALSE(l.outlier) << i << ": " << l.flag;
    const double e = 100.0 * (*l.position_mm - kDome * dirs[i]).norm() / kDome;
    s.mean += e / static_cast<double>(dirs.size());
    s.max = std::max(s.max, e);
  }
  if (out != nullptr) *out = r;
  return s;
}

TEST(CalibSphereRefine, TwoSpheresTriangulateNearLightsWithinOnePercentOfTheDome) {
  RigReport r;
  const Stats clean = triangulate(0.0, &r);
  const Stats linear = triangulate(0.0, nullptr, false);
  const Stats noisy = triangulate(2.0);
  // Reported, not required: a 1 degree light leaves a highlight of about a pixel, dimmer.
  const Stats small = triangulate(2.0, nullptr, true, 1.0);
  std::printf(
      "two spheres r = 25 mm, dome R = 500 mm: position error %% of R: noise-free mean %.3f "
      "max %.3f (linear triangulation mean %.3f max %.3f); noise 2 grey mean %.3f max %.3f; "
      "outline rms %.3f px, %d iterations; 1 degree light, noise 2 grey: mean %.3f max %.3f\n",
      clean.mean, clean.max, linear.mean, linear.max, noisy.mean, noisy.max, r.outline_rms_px,
      r.iterations, small.mean, small.max);
  EXPECT_LT(clean.max, kNearLightTargetPercent);
  EXPECT_LT(noisy.max, kNearLightTargetPercent);
  // The spheres' centres come back (found, then refined on their outlines).
  ASSERT_EQ(r.centres_camera.size(), 2u);
  EXPECT_LT((r.centres_camera[0] - camera_from_light({-90.0, 0.0, kSphere})).norm(),
            kSphereCentreTolMm);
  EXPECT_LT((r.centres_camera[1] - camera_from_light({90.0, 0.0, kSphere})).norm(),
            kSphereCentreTolMm);
  // Near lights: redundancy (4 measurements, 3 unknowns), so the residual means something.
  for (const RigLight& l : r.lights) EXPECT_LT(l.residual_px, kGoodResidualPx) << l.flag;
  const LightSet set = rig_light_set(r);
  ASSERT_EQ(set.size(), r.lights.size());
  EXPECT_TRUE(set.lights[0].position_mm.has_value());
}

// The same dome without the spheres' size or a plane: as distant lights most are outliers
// (the two spheres, 180 mm apart under a 500 mm dome, see each light along directions up to
// 20 degrees apart); near ones, in units of the sphere radius, explain them, and their
// directions from the origin (the optical axis at the spheres' mean depth) are what a fit
// there needs. Measured: near mean 0.02, max 0.05 degrees; distant mean 7.2, max 9.4.
constexpr double kNearFromEvidenceMeanDeg = 0.2;
constexpr double kNearFromEvidenceMaxDeg = 1.0;
TEST(CalibSphereRefine, NearLightsAreTakenFromTheEvidenceWithoutTheSpheresSize) {
  const DomeCapture d = render_dome(1.0);
  const auto& dirs = d.dirs;
  RigOptions o;
  o.sphere_count = 2;
  o.detection.camera.focal_px = d.rig.focal_px;
  o.detection.camera.principal_px = d.rig.principal_px;
  const RigReport near = calibrate_rig(d.images, d.names, o);
  o.near_from_evidence = false;
  const RigReport distant = calibrate_rig(d.images, d.names, o);
  // The light frame's origin: on the optical axis at the spheres' centres' depth.
  const Eigen::Vector3d origin(0.0, 0.0, kSphere);
  auto errors = [&](const RigReport& r) {
    Stats s;
    for (std::size_t i = 0; i < dirs.size(); ++i) {
      EXPECT_TRUE(r.lights[i].found) << r.lights[i].flag;
      const double e = angle_deg(r.lights[i].direction, kDome * dirs[i] - origin);
      s.mean += e / static_cast<double>(dirs.size());
      s.max = std::max(s.max, e);
    }
    return s;
  };
  const Stats en = errors(near), ed = errors(distant);
  std::printf(
      "two spheres, no size, dome R = 500 mm: distant model %d of %d outliers, mean %.3f max "
      "%.3f deg; %s (%s): %d outliers, mean %.3f max %.3f deg\n",
      distant.outliers(), distant.usable(), ed.mean, ed.max, near.model.c_str(),
      near.model_note.c_str(), near.outliers(), en.mean, en.max);
  EXPECT_EQ(distant.model, "pinhole distant");
  EXPECT_GT(2 * distant.outliers(), distant.usable());
  EXPECT_EQ(near.model, "pinhole near");
  EXPECT_TRUE(near.near_scale_free);
  EXPECT_EQ(near.usable(), static_cast<int>(dirs.size()));
  EXPECT_EQ(near.outliers(), 0);
  EXPECT_LE(en.mean, kNearFromEvidenceMeanDeg);
  EXPECT_LE(en.max, kNearFromEvidenceMaxDeg);
  for (const RigLight& l : near.lights) EXPECT_FALSE(l.position_mm.has_value());
  EXPECT_FALSE(rig_light_set(near).lights[0].position_mm.has_value());
}

// Two spheres, distant lights: in one image each sphere shows a different light (the left
// half of one render, the right half of another). Each highlight is clean and unambiguous,
// so only the disagreement between the spheres can tell.
TEST(CalibSphereRefine, SpheresThatDisagreeFlagTheLight) {
  const auto dirs = layout_directions("rings:40:5:10,75:3");
  synth::SphereRigOptions rig = two_sphere_rig();
  rig.noise_grey = 1.0;
  std::vector<Image> images;
  std::vector<fs::path> names;
  for (std::size_t i = 0; i < dirs.size(); ++i) {
    rig.light_dir = dirs[i];
    rig.seed = i + 1;
    images.push_back(synth::render_sphere_rig(rig));
    names.emplace_back("img" + std::to_string(i) + ".png");
  }
  constexpr std::size_t kBad = 2;
  rig.light_dir = layout_directions("rings:55:1:100")[0];
  const Image other = synth::render_sphere_rig(rig);
  for (int y = 0; y < rig.height; ++y) {
    for (int x = 0; x < rig.width / 2; ++x) images[kBad].at(x, y, 0) = other.at(x, y, 0);
  }
  RigOptions o;
  o.sphere_count = 2;
  o.detection.camera.focal_px = rig.focal_px;
  o.detection.camera.principal_px = rig.principal_px;
  RigReport r = calibrate_rig(images, names, o);
  EXPECT_EQ(r.model, "pinhole distant");
  double worst_good = 0.0, mean_err = 0.0;
  for (std::size_t i = 0; i < dirs.size(); ++i) {
    if (i == kBad) continue;
    EXPECT_FALSE(r.lights[i].outlier) << i << ": " << r.lights[i].flag;
    worst_good = std::max(worst_good, r.lights[i].residual_px);
    mean_err += angle_deg(r.lights[i].direction, dirs[i]) / static_cast<double>(dirs.size() - 1);
  }
  const RigLight& bad = r.lights[kBad];
  std::printf(
      "two spheres, distant lights, noise 1 grey: good lights residual <= %.3f px, mean "
      "error %.3f deg; the disagreeing light residual %.1f px, confidence %.3f: %s\n",
      worst_good, mean_err, bad.residual_px, bad.confidence, bad.flag.c_str());
  EXPECT_TRUE(bad.found);
  EXPECT_TRUE(bad.outlier);
  EXPECT_THAT(bad.flag, ::testing::HasSubstr("residual"));
  EXPECT_LT(bad.confidence, kDisagreeingConfidence);
  EXPECT_LT(mean_err, kTwoSphereMeanTolDeg);
  EXPECT_EQ(rig_light_set(r).size(), dirs.size());  // flagged, still there
  EXPECT_EQ(drop_outliers(&r), 1);                  // dropped when asked
  EXPECT_EQ(rig_light_set(r).size(), dirs.size() - 1);
}

// One sphere: a bright reflection of the scene planted in one image, brighter than the
// highlight. The residual cannot tell (one sphere, distant light); the second candidate can.
TEST(CalibSphereRefine, PlantedReflectionOnOneSphereIsFlaggedAsAmbiguous) {
  const auto dirs = layout_directions("rings:35:6,65:4:20,90:1");
  synth::SphereRigOptions rig;  // orthographic, 400 x 400, r = 160 px
  rig.noise_grey = 1.0;
  std::vector<Image> images;
  std::vector<fs::path> names;
  for (std::size_t i = 0; i < dirs.size(); ++i) {
    rig.light_dir = dirs[i];
    rig.seed = i + 1;
    images.push_back(synth::render_sphere_rig(rig));
    names.emplace_back("img" + std::to_string(i) + ".png");
  }
  constexpr std::size_t kBad = 4;
  for (int y = 0; y < 400; ++y) {
    for (int x = 0; x < 400; ++x) {
      if (std::hypot(x - 150.0, y - 250.0) <= 2.5) images[kBad].at(x, y, 0) = 1.0f;
    }
  }
  RigOptions o;
  o.spheres = {Circle{rig.centre_px, rig.radius_px, {}}};
  const RigReport r = calibrate_rig(images, names, o);
  for (std::size_t i = 0; i < dirs.size(); ++i) {
    if (i == kBad) continue;
    EXPECT_FALSE(r.lights[i].outlier) << i << ": " << r.lights[i].flag;
    EXPECT_LT(angle_deg(r.lights[i].direction, dirs[i]), kSingleSphereLightTolDeg);
    EXPECT_GT(r.lights[i].confidence, kCleanConfidence) << i;
  }
  const RigLight& bad = r.lights[kBad];
  std::printf(
      "planted reflection, one sphere: confidence %.3f (others >= %.3f): %s\n", bad.confidence,
      [&] {
        double m = 1.0;
        for (std::size_t i = 0; i < dirs.size(); ++i)
          if (i != kBad) m = std::min(m, r.lights[i].confidence);
        return m;
      }(),
      bad.flag.c_str());
  EXPECT_TRUE(bad.outlier);
  EXPECT_THAT(bad.flag, ::testing::HasSubstr("second candidate"));
  EXPECT_LT(bad.confidence, kAmbiguousConfidence);
  EXPECT_LT(bad.residual_px, kExactResidualPx);
}

std::string read_text(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

TEST(CalibSphereRefine, CommandTriangulatesWritesJsonAndDropsOutliersWhenAsked) {
  test::ScratchDir dir;
  const auto dirs = layout_directions("rings:45:4:10,80:1");
  synth::SphereRigOptions rig = two_sphere_rig();
  std::vector<std::string> args{"calibrate", "sphere"};
  for (std::size_t i = 0; i < dirs.size(); ++i) {
    rig.light_position_mm = camera_from_light(kDome * dirs[i]);
    Image img = synth::render_sphere_rig(rig);
    if (i == 1) {  // a planted reflection on the right sphere
      for (int y = 0; y < rig.height; ++y)
        for (int x = 0; x < rig.width; ++x)
          if (std::hypot(x - 560.0, y - 230.0) <= 2.0) img.at(x, y, 0) = 1.0f;
    }
    char name[32];
    std::snprintf(name, sizeof(name), "s%zu.png", i);
    write_image(dir / name, img.view());
    args.push_back((dir / name).string());
  }
  write_plane_json(dir / "plane.json", plane_of_the_scene());
  auto near = args;
  near.insert(near.end(), {"--spheres", "2", "--focal-px", "1500", "--principal", "319.5,199.5",
                           "--sphere-radius-mm", "25", "--plane", (dir / "plane.json").string(),
                           "-o", (dir / "l.lp").string(), "--json", (dir / "l.json").string(),
                           "--report", (dir / "r.json").string()});
  const auto r = test::run_ptmkit(near);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_THAT(r.out, ::testing::HasSubstr("5 of 5 lights usable"));
  EXPECT_THAT(r.out, ::testing::HasSubstr("outlier s1.png"));
  const LightSet lp = read_lp(dir / "l.lp");
  EXPECT_EQ(lp.size(), dirs.size());
  const auto report = nlohmann::json::parse(std::ifstream(dir / "r.json"));
  EXPECT_EQ(report["model"], "pinhole near");
  EXPECT_EQ(report["outliers"], 1);
  const auto& p0 = report["lights"][0]["position_mm"];
  const Eigen::Vector3d truth = kDome * dirs[0];
  EXPECT_LT((Eigen::Vector3d(p0[0], p0[1], p0[2]) - truth).norm(),
            kNearLightTargetPercent / 100.0 * kDome);
  EXPECT_TRUE(fs::exists(dir / "l.json"));
  auto dropped = near;
  dropped.push_back("--drop-outliers");
  const auto d = test::run_ptmkit(dropped);
  ASSERT_EQ(d.exit_code, 0) << d.err;
  EXPECT_EQ(read_lp(dir / "l.lp").size(), dirs.size() - 1);
  // Circles given (repeatable, before the images), no sphere size: the spheres disagree about
  // most lights as distant ones, so near ones are taken from the evidence and the command
  // says so; told --distant-lights, it keeps the distant model and says what the
  // disagreement suggests.
  std::vector<std::string> given{"calibrate",         "sphere",   "--sphere",
                                 "84.28,199.5,65.66", "--sphere", "554.72,199.5,65.66"};
  given.insert(given.end(), args.begin() + 2, args.end());
  given.insert(given.end(),
               {"--focal-px", "1500", "--principal", "319.5,199.5", "-o", (dir / "d.lp").string()});
  const auto g = test::run_ptmkit(given);
  ASSERT_EQ(g.exit_code, 0) << g.err;
  EXPECT_THAT(g.out, ::testing::HasSubstr("pinhole near model"));
  EXPECT_THAT(g.out, ::testing::HasSubstr("chosen from the evidence"));
  EXPECT_EQ(read_lp(dir / "d.lp").size(), dirs.size());
  given.push_back("--distant-lights");
  const auto gd = test::run_ptmkit(given);
  ASSERT_EQ(gd.exit_code, 0) << gd.err;
  EXPECT_THAT(gd.out, ::testing::HasSubstr("pinhole distant model"));
  EXPECT_THAT(gd.out, ::testing::HasSubstr("near lights?"));
  // The same intrinsics from a `calibrate camera` file, or from the lens and sensor size,
  // give the same lights; two sources at once are refused.
  const std::string focal_lp = read_text(dir / "l.lp");
  CameraIntrinsics cam;
  cam.width_px = rig.width;
  cam.height_px = rig.height;
  cam.fx = cam.fy = 1500.0;
  cam.cx = 319.5;
  cam.cy = 199.5;
  write_camera_json(dir / "camera.json", cam);
  auto with_camera = near;
  const auto focal_at = std::find(with_camera.begin(), with_camera.end(), "--focal-px");
  *focal_at = "--camera";
  *(focal_at + 1) = (dir / "camera.json").string();
  with_camera.push_back("--drop-outliers");
  const auto c = test::run_ptmkit(with_camera);
  ASSERT_EQ(c.exit_code, 0) << c.err;
  EXPECT_EQ(read_text(dir / "l.lp"), focal_lp);
  auto with_lens = with_camera;
  const auto camera_at = std::find(with_lens.begin(), with_lens.end(), "--camera");
  *camera_at = "--focal-mm";
  *(camera_at + 1) = "35";  // 35 mm on a sensor 640 * 35 / 1500 mm wide: f = 1500 px
  with_lens.insert(with_lens.end(), {"--sensor-width-mm", std::to_string(640.0 * 35.0 / 1500.0)});
  const auto l = test::run_ptmkit(with_lens);
  ASSERT_EQ(l.exit_code, 0) << l.err;
  EXPECT_EQ(read_lp(dir / "l.lp").size(), dirs.size() - 1);
  auto both = with_camera;
  both.insert(both.end(), {"--focal-px", "1500"});
  const auto b = test::run_ptmkit(both);
  EXPECT_EQ(b.exit_code, 1);
  EXPECT_THAT(b.err, ::testing::HasSubstr("focal length once"));
  // Positions need two spheres: one sphere with a radius in mm is refused.
  auto one = args;
  one.insert(one.end(), {"--spheres", "1", "--focal-px", "1500", "--sphere-radius-mm", "25", "-o",
                         (dir / "x.lp").string()});
  const auto e = test::run_ptmkit(one);
  EXPECT_EQ(e.exit_code, 1);
  EXPECT_THAT(e.err, ::testing::HasSubstr("two or more spheres"));
  EXPECT_FALSE(fs::exists(dir / "x.lp"));
}

}  // namespace
}  // namespace ptmkit::calib
