// Near lights: synth's point lights on a dome of finite radius, and the fit's per-texel model.
#include "ptmkit/fit/near_light.h"

#include <cmath>
#include <cstring>
#include <fstream>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "ptmkit/calib/dome.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/light_layout.h"
#include "ptmkit/core/light_set.h"
#include "ptmkit/core/plane.h"
#include "ptmkit/fit/fit.h"
#include "ptmkit/synth/synth.h"
#include "relit_error.h"
#include "test_util.h"
#include "tolerances.h"

using ::testing::HasSubstr;

namespace ptmkit::fit {
namespace {

using test::kDoubleRoundoff;
using test::kDoubleSolveRoundoff;

// The polynomial world under near lights, float samples (1e-7 relative) through each texel's
// 6 x 6 solve: measured worst coefficient error 3e-8.
constexpr double kPerTexelCoeffTol = 2e-5;
// The distant model cannot follow per-texel directions: measured worst coefficient error 0.063
// (fall-off off) and 0.26 (on).
constexpr double kDistantModelMinCoeffError = 0.05;
// Distance from the distant-light floor, distant model against per-texel model with fall-off:
// measured 15.96 against 2.60 grey levels (6.1 times).
constexpr double kFalloffModelGainFactor = 5.0;
// Distance from the diffuse truth, distant model against per-texel model with fall-off:
// measured 19.05 against 10.87 grey levels (1.75 times).
constexpr double kTruthGainFactor = 1.6;

bool same_bits(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() &&
         (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0);
}

// A near-light capture rendered in memory, with its light set (positions) and plane.
struct Capture {
  synth::SynthOptions options;
  synth::Scene scene;
  std::vector<Eigen::Vector3d> dirs;
  std::vector<Image> images;
  LightSet lights;
  SamplePlane plane;
};

Capture render(const synth::SynthOptions& o) {
  Capture c;
  c.options = o;
  c.scene = synth::build_scene(o);
  c.dirs = synth::resolve_lights(o);
  for (std::size_t i = 0; i < c.dirs.size(); ++i) {
    c.images.push_back(synth::render_light(c.scene, o, c.dirs[i], static_cast<int>(i)).observed);
    Light l;
    l.direction = c.dirs[i];
    if (o.dome_radius_mm > 0.0) l.position_mm = o.dome_radius_mm * c.dirs[i];
    c.lights.lights.push_back(l);
  }
  c.plane = orthographic_plane(o.width, o.height, o.mm_per_px);
  return c;
}

CoefficientMap fit_map(const Capture& c, bool near, bool falloff, int threads = 0) {
  FitOptions fo;
  fo.threads = threads;
  if (near) fo.near.plane = c.plane;
  fo.near.falloff = falloff;
  CoefficientMap map;
  CoefficientMapSink sink(&map);
  (void)fit_images(c.images, c.lights, fo, sink);
  return map;
}

double max_coeff_error(const CoefficientMap& got, const CoefficientMap& truth) {
  double worst = 0.0;
  for (std::size_t i = 0; i < truth.coeffs.size(); ++i) {
    worst = std::max(worst, std::abs(static_cast<double>(got.coeffs[i]) - truth.coeffs[i]));
  }
  return worst;
}

// RMS difference in grey levels between a map relit at `dirs` and reference images.
double relit_rms_grey(const CoefficientMap& map, const std::vector<Image>& ref,
                      const std::vector<Eigen::Vector3d>& dirs) {
  return test::relit_error(map, ref, dirs).rms_grey;
}

std::vector<Image> relit(const CoefficientMap& map, const std::vector<Eigen::Vector3d>& dirs) {
  std::vector<Image> out;
  for (const auto& d : dirs) {
    Image img(map.width, map.height, 3, ColourSpace::kLinear);
    for (int y = 0; y < map.height; ++y)
      for (int x = 0; x < map.width; ++x) map.evaluate(x, y, d.x(), d.y(), &img.at(x, y, 0));
    out.push_back(std::move(img));
  }
  return out;
}

synth::SynthOptions polynomial_near(bool falloff) {
  synth::SynthOptions o = synth::preset_options("polynomial");  // 64x64 float, no noise
  o.mm_per_px = 1.5;                                            // a 94.5 mm field
  o.dome_radius_mm = 250.0;
  o.inverse_square_falloff = falloff;
  return o;
}

TEST(NearLightSynth, TexelDirectionsAndFalloffFollowTheGeometry) {
  synth::SynthOptions o = polynomial_near(true);
  o.width = o.height = 65;  // a centre pixel at the plane origin
  const synth::Scene scene = synth::build_scene(o);
  const Eigen::Vector3d nominal = direction_from_angles_deg(30.0, 40.0);
  double f = 0.0;
  const Eigen::Vector3d centre = synth::texel_light_dir(scene, o, nominal, 32, 32, &f);
  EXPECT_LT((centre - nominal).norm(), kDoubleRoundoff);
  EXPECT_NEAR(f, 1.0, kDoubleRoundoff);
  // Top-left pixel: plane point (-48, +48, 0) mm.
  const Eigen::Vector3d p = 250.0 * nominal;
  const Eigen::Vector3d v = p - Eigen::Vector3d(-48.0, 48.0, 0.0);
  const Eigen::Vector3d corner = synth::texel_light_dir(scene, o, nominal, 0, 0, &f);
  EXPECT_LT((corner - v.normalized()).norm(), kDoubleRoundoff);
  EXPECT_NEAR(f, p.squaredNorm() / v.squaredNorm(), kDoubleRoundoff);
  // Distant lights: the nominal direction everywhere.
  o.dome_radius_mm = 0.0;
  EXPECT_EQ(synth::texel_light_dir(scene, o, nominal, 0, 0, &f), nominal.normalized());
  EXPECT_EQ(f, 1.0);
}

TEST(NearLightSynth, RefusesLightsBelowTheReliefTop) {
  synth::SynthOptions o = synth::preset_options("matte");
  o.width = o.height = 32;
  o.mm_per_px = 10.0;        // relief 3.2 px = 32 mm high
  o.dome_radius_mm = 100.0;  // the 10-degree ring is 17 mm up
  test::ScratchDir dir;
  try {
    (void)synth::render_capture(o, dir / "out");
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("not above the relief's top"));
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "out" / "lights.lp"));
}

// The polynomial world under near lights: every texel's samples are exactly its biquadratic at
// its own light directions (times the fall-off), so the per-texel model recovers the stored
// coefficients to float precision, and the distant model cannot.
TEST(NearLightFit, PolynomialWorldIsRecoveredExactly) {
  for (const bool falloff : {false, true}) {
    const Capture c = render(polynomial_near(falloff));
    const double near_err = max_coeff_error(fit_map(c, true, falloff), c.scene.coefficients);
    const double distant_err = max_coeff_error(fit_map(c, false, false), c.scene.coefficients);
    std::printf(
        "polynomial world, near lights (fall-off %s): max coefficient error near %.3g, "
        "distant %.3g\n",
        falloff ? "on" : "off", near_err, distant_err);
    EXPECT_LT(near_err, kPerTexelCoeffTol);
    EXPECT_GT(distant_err, kDistantModelMinCoeffError);
  }
}

// A matte relief of 128 px over 153 mm under a 400 mm dome (49 lights, cast shadows, 8-bit,
// noise 1 grey). Relit at 22 held-out distant lights: the error of each fit against the fit of
// the same scene captured under distant lights (the polynomial's own limit, "floor"), and
// against the diffuse truth. Measured (bench/near_light --size 128 --mm-per-px 1.2): vs floor
// distant 15.96, near 12.34, near + fall-off 2.60 grey; vs truth 19.05, 15.09, 10.87 (floor
// 10.49).
TEST(NearLightFit, PerTexelModelRemovesMostOfTheNearLightError) {
  synth::SynthOptions o = synth::preset_options("matte");
  o.width = o.height = 128;
  o.mm_per_px = 1.2;
  o.dome_radius_mm = 400.0;
  const Capture c = render(o);
  const auto held = ring_layout(parse_rings("20:8:22.5,40:8:11.25,60:6:30"));
  synth::SynthOptions t = o;
  t.dome_radius_mm = 0.0;
  t.sensor.bits = 32;
  t.sensor.file_type = synth::FileType::kExr;
  t.sensor.noise_sigma_grey = 0.0;
  std::vector<Image> truth;
  for (std::size_t k = 0; k < held.size(); ++k) {
    truth.push_back(synth::render_light(c.scene, t, held[k], 1000 + static_cast<int>(k)).diffuse);
  }
  synth::SynthOptions d = o;
  d.dome_radius_mm = 0.0;
  const Capture floor_capture = render(d);
  const auto floor_relit = relit(fit_map(floor_capture, false, false), held);

  const CoefficientMap distant = fit_map(c, false, false);
  const CoefficientMap near = fit_map(c, true, false);
  const CoefficientMap near_falloff = fit_map(c, true, true);
  const double floor_d = relit_rms_grey(distant, floor_relit, held);
  const double floor_n = relit_rms_grey(near, floor_relit, held);
  const double floor_nf = relit_rms_grey(near_falloff, floor_relit, held);
  const double truth_d = relit_rms_grey(distant, truth, held);
  const double truth_nf = relit_rms_grey(near_falloff, truth, held);
  std::printf(
      "near-light relief: vs floor distant %.2f, near %.2f, near+falloff %.2f grey; vs "
      "truth distant %.2f, near+falloff %.2f grey\n",
      floor_d, floor_n, floor_nf, truth_d, truth_nf);
  EXPECT_GT(floor_d, kFalloffModelGainFactor * floor_nf);
  EXPECT_LT(floor_n, floor_d);
  EXPECT_LT(floor_nf, floor_n);
  EXPECT_GT(truth_d, kTruthGainFactor * truth_nf);
}

TEST(NearLightFit, DeterministicWhateverTheThreadCount) {
  synth::SynthOptions o = synth::preset_options("matte");
  o.width = o.height = 48;
  o.mm_per_px = 2.0;
  o.dome_radius_mm = 300.0;
  const Capture c = render(o);
  FitOptions fo;
  fo.near.plane = c.plane;
  fo.near.falloff = true;
  fo.model = ColourModel::kLRGB;
  CoefficientMap a, b;
  fo.threads = 1;
  fo.band_rows = 5;
  {
    CoefficientMapSink sink(&a);
    (void)fit_images(c.images, c.lights, fo, sink);
  }
  fo.threads = 2;
  fo.band_rows = 16;
  {
    CoefficientMapSink sink(&b);
    (void)fit_images(c.images, c.lights, fo, sink);
  }
  EXPECT_TRUE(same_bits(a.coeffs, b.coeffs));
  EXPECT_TRUE(same_bits(a.colour, b.colour));
}

TEST(NearLightFit, ReportsTheModelSpreadAndFalloff) {
  const Capture c = render(polynomial_near(true));
  FitOptions fo;
  fo.near.plane = c.plane;
  fo.near.falloff = true;
  CoefficientMap map;
  CoefficientMapSink sink(&map);
  const FitReport r = fit_images(c.images, c.lights, fo, sink);
  EXPECT_EQ(r.light_model.model, fit::LightModel::kNear);
  EXPECT_TRUE(r.light_model.falloff_corrected);
  EXPECT_EQ(r.light_model.singular_texels, 0u);
  // The spread of the overhead light across a 94.5 mm field at 250 mm: atan(47.25 sqrt 2 /
  // 250) at the corners; lower lights turn more.
  const double overhead = std::atan(47.25 * std::sqrt(2.0) / 250.0) * 180.0 / 3.14159265358979;
  EXPECT_GT(r.light_model.max_spread_deg, overhead);
  EXPECT_LT(r.light_model.min_falloff, 1.0);
  EXPECT_GT(r.light_model.max_falloff, 1.0);
  const auto j = nlohmann::json::parse(r.to_json());
  EXPECT_EQ(j["light_model"]["model"], "near");
  EXPECT_TRUE(j["light_model"].contains("max_spread_deg"));
}

TEST(NearLightFit, PositionsWithoutAPlaneKeepTheDistantPathBitForBit) {
  const Capture c = render(polynomial_near(false));
  CoefficientMap with_positions, dirs_only;
  FitReport r;
  {
    CoefficientMapSink sink(&with_positions);
    r = fit_images(c.images, c.lights, {}, sink);
  }
  {
    CoefficientMapSink sink(&dirs_only);
    (void)fit_images(c.images, c.dirs, {}, sink);
  }
  EXPECT_TRUE(same_bits(with_positions.coeffs, dirs_only.coeffs));
  EXPECT_EQ(r.light_model.model, fit::LightModel::kDistant);
  EXPECT_THAT(r.light_model.note, HasSubstr("no sample plane"));
}

TEST(NearLightFit, ClearErrors) {
  const Capture c = render(polynomial_near(false));
  CoefficientMap map;
  CoefficientMapSink sink(&map);
  auto expect_error = [&](const LightSet& lights, const FitOptions& fo, const char* what) {
    try {
      (void)fit_images(c.images, lights, fo, sink);
      ADD_FAILURE() << "expected an error containing: " << what;
    } catch (const Error& e) {
      EXPECT_THAT(e.what(), HasSubstr(what));
    }
  };
  FitOptions fo;
  fo.near.plane = orthographic_plane(c.options.width + 1, c.options.height, 1.5);
  expect_error(c.lights, fo, "sample plane is for 65x64 images but the capture is 64x64");
  fo.near.plane = c.plane;
  LightSet missing = c.lights;
  missing.lights[3].position_mm.reset();
  expect_error(missing, fo, "light 4");
  expect_error(missing, fo, "has no position_mm");
  fo.solver = Solver::kRobust;
  expect_error(c.lights, fo, "ls and ridge");
  FitOptions no_plane;
  no_plane.near.falloff = true;
  expect_error(c.lights, no_plane, "fall-off correction needs");
  LightSet below = c.lights;
  below.lights[0].position_mm = Eigen::Vector3d(10.0, 0.0, -1.0);
  FitOptions ls;
  ls.near.plane = c.plane;
  expect_error(below, ls, "z <= 0");
}

// The CLI: synth writes lights.json and plane.json; fit reads them back.
TEST(NearLightCli, SynthAndFitRoundTrip) {
  test::ScratchDir dir;
  const std::string out = (dir / "cap").string();
  auto r = test::run_ptmkit({"synth", "--out", out, "--preset", "matte", "--size", "32",
                             "--dome-radius", "300", "--mm-per-px", "3", "--lights", "icosa"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const LightSet json = calib::read_dome_json(dir / "cap" / "lights.json");
  ASSERT_EQ(json.size(), 40u);
  ASSERT_TRUE(json.lights[0].position_mm.has_value());
  EXPECT_NEAR(json.lights[0].position_mm->norm(), 300.0, kDoubleSolveRoundoff);
  const SamplePlane plane = read_plane_json(dir / "cap" / "plane.json");
  EXPECT_EQ(plane.width_px, 32);
  EXPECT_NEAR(plane.mean_mm_per_px(), 3.0, kDoubleRoundoff);
  std::ifstream tj(dir / "cap" / "truth.json");
  const auto truth = nlohmann::json::parse(tj);
  EXPECT_EQ(truth["dome_radius_mm"], 300.0);
  EXPECT_EQ(truth["mm_per_px"], 3.0);

  const std::string lp = out + "/lights.lp";
  const std::string report = (dir / "r.json").string();
  r = test::run_ptmkit({"fit", lp, "-o", (dir / "n.ptm").string(), "--lights-json",
                        out + "/lights.json", "--plane", out + "/plane.json", "--falloff",
                        "--report", report});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_THAT(r.out, HasSubstr("near lights: per-texel directions"));
  std::ifstream rj(report);
  const auto rep = nlohmann::json::parse(rj);
  EXPECT_EQ(rep["light_model"]["model"], "near");
  EXPECT_EQ(rep["light_model"]["falloff_corrected"], true);

  // Positions from a JSON without them, a fall-off without a plane: errors, never a silent
  // distant fit (the library-level cases are in NearLightFit.ClearErrors).
  write_light_json(dir / "dirs.json", read_lp(lp));  // directions only
  r = test::run_ptmkit({"fit", lp, "-o", (dir / "b.ptm").string(), "--lights-json",
                        (dir / "dirs.json").string(), "--plane", out + "/plane.json"});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_THAT(r.err, HasSubstr("has no position_mm"));
  EXPECT_FALSE(std::filesystem::exists(dir / "b.ptm"));
  // A dome description is not a list of lights: refused, saying how to make one.
  {
    std::ofstream f(dir / "dome.json");
    f << R"({"layout": "icosa", "radius_mm": 300})";
  }
  r = test::run_ptmkit({"fit", lp, "-o", (dir / "c.ptm").string(), "--lights-json",
                        (dir / "dome.json").string(), "--plane", out + "/plane.json"});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_THAT(r.err, HasSubstr("calibrate dome"));
  r = test::run_ptmkit({"fit", lp, "-o", (dir / "d.ptm").string(), "--falloff"});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_THAT(r.err, HasSubstr("fall-off correction needs"));
  EXPECT_FALSE(std::filesystem::exists(dir / "d.ptm"));
}

}  // namespace
}  // namespace ptmkit::fit
