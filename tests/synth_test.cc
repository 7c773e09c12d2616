// Tests of the synth stage: scenes, shadows, shading, sensor, labels, presets, capture folders.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "ptmkit/core/colour.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/core/light_set.h"
#include "ptmkit/core/parallel.h"
#include "ptmkit/synth/synth.h"
#include "test_util.h"

namespace fs = std::filesystem;

namespace ptmkit::synth {
namespace {

// One grey level of 8-bit output, in normalised units.
constexpr double kGrey8 = 1.0 / 255.0;
// Float rounding of values around 1 (images are float32).
constexpr double kFloatTol = 1e-6;

SynthOptions small_options(const std::string& preset = "default", int size = 64) {
  SynthOptions o = preset_options(preset);
  o.width = size;
  o.height = size;
  o.seed = ptmkit::test::test_seed();
  return o;
}

std::string read_bytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::vector<fs::path> all_files(const fs::path& dir) {
  std::vector<fs::path> files;
  for (const auto& e : fs::recursive_directory_iterator(dir)) {
    if (e.is_regular_file()) files.push_back(fs::relative(e.path(), dir));
  }
  std::sort(files.begin(), files.end());
  return files;
}

// --- scenes -------------------------------------------------------------------------------

TEST(SynthScene, ReliefMapsAreInRange) {
  const SynthOptions o = small_options();
  const Scene s = build_scene(o);
  ASSERT_EQ(s.kind, SceneKind::kRelief);
  ASSERT_EQ(s.normals.width(), 64);
  const double max_height = o.relief.relief_height_frac * o.width;
  EXPECT_NEAR(s.max_height_px, max_height, 1e-4);
  EXPECT_NEAR(*std::min_element(s.height_px.begin(), s.height_px.end()), 0.0, 1e-6);
  for (int y = 0; y < s.height; ++y) {
    for (int x = 0; x < s.width; ++x) {
      const Eigen::Vector3d n(s.normals.at(x, y, 0), s.normals.at(x, y, 1), s.normals.at(x, y, 2));
      ASSERT_NEAR(n.norm(), 1.0, kFloatTol) << x << "," << y;
      ASSERT_GT(n.z(), 0.0);
      for (int c = 0; c < 3; ++c) {
        ASSERT_GE(s.albedo.at(x, y, c), 0.3f);
        ASSERT_LE(s.albedo.at(x, y, c), 0.9f);
      }
    }
  }
}

TEST(SynthScene, NormalsFollowTheSlope) {
  // A ramp rising toward +x (to the right) and toward the image top (+y of the light frame):
  // the normal leans to -x and -y, by the slopes.
  constexpr int kSize = 16;
  constexpr double kSlopeX = 0.5;
  constexpr double kSlopeY = 0.25;
  std::vector<float> h(kSize * kSize);
  for (int y = 0; y < kSize; ++y) {
    for (int x = 0; x < kSize; ++x) {
      h[y * kSize + x] = static_cast<float>(kSlopeX * x + kSlopeY * (kSize - 1 - y));
    }
  }
  const Scene s = scene_from_height(kSize, kSize, h);
  const Eigen::Vector3d expected = Eigen::Vector3d(-kSlopeX, -kSlopeY, 1.0).normalized();
  for (int y = 0; y < kSize; ++y) {
    for (int x = 0; x < kSize; ++x) {
      for (int c = 0; c < 3; ++c) ASSERT_NEAR(s.normals.at(x, y, c), expected[c], kFloatTol);
    }
  }
}

TEST(SynthScene, SeedChangesTheScene) {
  SynthOptions a = small_options();
  SynthOptions b = a;
  b.seed = a.seed + 1;
  EXPECT_NE(build_scene(a).height_px, build_scene(b).height_px);
  EXPECT_EQ(build_scene(a).height_px, build_scene(a).height_px);
}

// --- shadows --------------------------------------------------------------------------------

// A wall of height kWall px in columns [20, 22] on flat ground, lit from +x (the right) at
// elevation e: its shadow covers the ground to its left for kWall / tan(e) pixels.
TEST(SynthShadow, WallCastsShadowOfTheRightLength) {
  constexpr int kW = 64;
  constexpr int kH = 16;
  constexpr int kWallX0 = 20;
  constexpr int kWallX1 = 22;
  constexpr double kWall = 10.0;
  std::vector<float> h(kW * kH, 0.0f);
  for (int y = 0; y < kH; ++y) {
    for (int x = kWallX0; x <= kWallX1; ++x) h[y * kW + x] = static_cast<float>(kWall);
  }
  const Scene s = scene_from_height(kW, kH, h);
  for (const double elevation : {45.0, 30.0, 60.0}) {
    const double length = kWall / std::tan(elevation * M_PI / 180.0);
    const auto mask = cast_shadow_mask(s, direction_from_angles_deg(elevation, 0.0));
    const int y = kH / 2;
    // The bilinear ramp at the wall's foot starts one pixel before it: the shadow reaches
    // from the wall to about `length` px, within one pixel either side.
    for (int x = 0; x < kWallX0; ++x) {
      const double d = kWallX0 - x;
      if (d < length - 1.0) {
        EXPECT_EQ(mask[y * kW + x], 1) << "elevation " << elevation << " x " << x;
      }
      if (d > length + 1.0) {
        EXPECT_EQ(mask[y * kW + x], 0) << "elevation " << elevation << " x " << x;
      }
    }
    // Nothing on the lit side of the wall is shadowed.
    for (int x = kWallX1 + 1; x < kW; ++x) EXPECT_EQ(mask[y * kW + x], 0) << x;
  }
  // Light from the image top (+y): the wall's shadow falls along the wall, not beside it.
  const auto top = cast_shadow_mask(s, direction_from_angles_deg(30.0, 90.0));
  for (int x = 0; x < kW; ++x) {
    if (x < kWallX0 - 1 || x > kWallX1 + 1) {
      EXPECT_EQ(top[(kH / 2) * kW + x], 0) << x;
    }
  }
  // Overhead light: no cast shadow at all.
  const auto overhead = cast_shadow_mask(s, Eigen::Vector3d(0.0, 0.0, 1.0));
  EXPECT_EQ(std::count(overhead.begin(), overhead.end(), 1), 0);
}

TEST(SynthShadow, ShadowFallsAwayFromTheLightInImageRows) {
  // A post in the middle, lit from the image top (+y): its shadow lies below it (larger rows).
  constexpr int kSize = 48;
  std::vector<float> h(kSize * kSize, 0.0f);
  for (int y = 22; y <= 25; ++y) {
    for (int x = 22; x <= 25; ++x) h[y * kSize + x] = 8.0f;
  }
  const Scene s = scene_from_height(kSize, kSize, h);
  const auto mask = cast_shadow_mask(s, direction_from_angles_deg(45.0, 90.0));
  EXPECT_EQ(mask[30 * kSize + 23], 1);  // below the post
  EXPECT_EQ(mask[17 * kSize + 23], 0);  // above the post
}

TEST(SynthShadow, FullCaptureShadowsAreQuick) {
  // 256x256 under the 49 lights: the march skips empty space, so this takes a fraction of a
  // second in a release build.
  const SynthOptions o = preset_options("default");
  const Scene s = build_scene(o);
  const auto lights = resolve_lights(o);
  const auto start = std::chrono::steady_clock::now();
  std::size_t shadowed = 0;
  for (std::size_t i = 0; i < lights.size(); ++i) {
    const auto mask = cast_shadow_mask(s, lights[i]);
    shadowed += static_cast<std::size_t>(std::count(mask.begin(), mask.end(), 1));
  }
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  RecordProperty("shadow_seconds", std::to_string(seconds));
  std::printf("[ timing   ] 49 shadow masks at 256x256: %.3f s\n", seconds);
  EXPECT_GT(shadowed, 0u);
  // A loose bound that still catches a march that forgot to stop (minutes).
  EXPECT_LT(seconds, 20.0);
}

// --- shading and sensor ----------------------------------------------------------------------

TEST(SynthRender, DiffuseTruthIsLambertThroughTheSensor) {
  for (const bool srgb : {false, true}) {
    SynthOptions o = small_options("ambient");
    o.sensor.srgb = srgb;
    o.sensor.bits = srgb ? 16 : 8;
    const double levels = srgb ? 65535.0 : 255.0;
    const Scene s = build_scene(o);
    const Eigen::Vector3d l = direction_from_angles_deg(35.0, 120.0);
    const RenderedLight r = render_light(s, o, l, 3);
    EXPECT_EQ(r.diffuse.colour_space(), srgb ? ColourSpace::kSRGB : ColourSpace::kLinear);
    for (int y = 0; y < s.height; ++y) {
      for (int x = 0; x < s.width; ++x) {
        const Eigen::Vector3d n(s.normals.at(x, y, 0), s.normals.at(x, y, 1),
                                s.normals.at(x, y, 2));
        for (int c = 0; c < 3; ++c) {
          const double a = s.albedo.at(x, y, c);
          double v = o.sensor.exposure * a * (std::max(0.0, n.dot(l)) + o.material.ambient);
          if (srgb) v = linear_to_srgb(v);
          const double expected = std::round(std::clamp(v, 0.0, 1.0) * levels) / levels;
          ASSERT_NEAR(r.diffuse.at(x, y, c), expected, kFloatTol) << x << "," << y << "," << c;
        }
      }
    }
  }
}

TEST(SynthRender, BrightestDiffuseIsAboutNinetyPercent) {
  for (const std::string preset : {"default", "ambient"}) {
    const SynthOptions o = small_options(preset);
    const Scene s = build_scene(o);
    double brightest = 0.0;
    for (int y = 0; y < s.height; ++y) {
      for (int x = 0; x < s.width; ++x) {
        for (int c = 0; c < 3; ++c) {
          brightest = std::max(
              brightest, o.sensor.exposure * s.albedo.at(x, y, c) * (1.0 + o.material.ambient));
        }
      }
    }
    EXPECT_LE(brightest, 0.9 + kFloatTol) << preset;
    EXPECT_GT(brightest, 0.75) << preset;
  }
}

TEST(SynthRender, LabelsAgreeWithTheImages) {
  const SynthOptions o = small_options("default");
  const Scene s = build_scene(o);
  const double sigma = o.sensor.noise_sigma_grey * kGrey8;
  // 5 sigma of noise plus half a grey level of quantisation.
  const double noise_tol = 5.0 * sigma + 0.5 * kGrey8;
  const double threshold = o.highlight_threshold_grey * kGrey8;
  std::size_t counts[3] = {0, 0, 0};
  std::size_t cast_darker = 0;
  const auto lights = resolve_lights(o);
  for (std::size_t i = 0; i < lights.size(); i += 4) {
    const RenderedLight r = render_light(s, o, lights[i], static_cast<int>(i));
    for (int y = 0; y < s.height; ++y) {
      for (int x = 0; x < s.width; ++x) {
        const std::uint8_t label = r.labels[y * s.width + x];
        ASSERT_LE(label, kLabelHighlight);
        ++counts[label];
        double obs = 0.0;
        double truth = 0.0;
        for (int c = 0; c < 3; ++c) {
          obs += r.observed.at(x, y, c) / 3.0;
          truth += r.diffuse.at(x, y, c) / 3.0;
        }
        if (label == kLabelShadow) {
          // Shadowed samples are never brighter than the diffuse truth, and cast shadows
          // on surfaces facing the light are clearly darker.
          ASSERT_LE(obs, truth + noise_tol);
          if (truth > 10.0 * kGrey8 && obs < truth - noise_tol) ++cast_darker;
        } else if (label == kLabelHighlight) {
          const bool clipped = std::max({r.observed.at(x, y, 0), r.observed.at(x, y, 1),
                                         r.observed.at(x, y, 2)}) >= 1.0f;
          if (!clipped) {
            ASSERT_GT(obs, truth + threshold / 3.0 - noise_tol) << x << "," << y;
          }
        } else {
          // Inliers are the truth plus noise and a specular tail below the threshold.
          for (int c = 0; c < 3; ++c) {
            ASSERT_NEAR(r.observed.at(x, y, c), r.diffuse.at(x, y, c), threshold + noise_tol)
                << x << "," << y << "," << c;
          }
        }
      }
    }
  }
  // The default preset has all three kinds, inliers the most.
  EXPECT_GT(counts[kLabelShadow], 100u);
  EXPECT_GT(counts[kLabelHighlight], 100u);
  EXPECT_GT(counts[kLabelInlier], counts[kLabelShadow] + counts[kLabelHighlight]);
  EXPECT_GT(cast_darker, 50u);
}

TEST(SynthRender, MatteHasNoHighlightsAndNoShadowsWithoutCasting) {
  SynthOptions o = small_options("matte");
  o.cast_shadows = false;
  o.relief.relief_height_frac = 0.02;  // gentle: no attached shadows at 30 degrees
  const Scene s = build_scene(o);
  const RenderedLight r = render_light(s, o, direction_from_angles_deg(50.0, 30.0), 0);
  EXPECT_EQ(std::count(r.labels.begin(), r.labels.end(), kLabelHighlight), 0);
  EXPECT_EQ(std::count(r.labels.begin(), r.labels.end(), kLabelShadow), 0);
}

TEST(SynthRender, NoiseHasTheRequestedSigma) {
  SynthOptions o = small_options("matte", 128);
  o.sensor.noise_sigma_grey = 3.0;
  o.cast_shadows = false;
  const Scene s = build_scene(o);
  const RenderedLight r = render_light(s, o, Eigen::Vector3d(0.0, 0.0, 1.0), 7);
  double sum = 0.0;
  double sum_sq = 0.0;
  double n = 0.0;
  for (std::size_t i = 0; i < r.observed.size(); ++i) {
    const double d = (r.observed.data()[i] - r.diffuse.data()[i]) * 255.0;
    sum += d;
    sum_sq += d * d;
    n += 1.0;
  }
  const double mean = sum / n;
  const double sd = std::sqrt(sum_sq / n - mean * mean);
  // 49k samples: the sd estimate is good to about 1%; quantisation adds 1/12 grey^2.
  EXPECT_NEAR(mean, 0.0, 0.1);
  EXPECT_NEAR(sd, std::sqrt(9.0 + 1.0 / 12.0), 0.1);
}

TEST(SynthRender, SameResultWhateverTheThreadCount) {
  const SynthOptions o = small_options("default", 96);
  RenderedLight one;
  RenderedLight two;
  std::vector<float> h1;
  {
    ThreadLimit limit(1);
    const Scene s = build_scene(o);
    h1 = s.height_px;
    one = render_light(s, o, direction_from_angles_deg(20.0, 200.0), 5);
  }
  {
    ThreadLimit limit(2);
    const Scene s = build_scene(o);
    EXPECT_EQ(s.height_px, h1);
    two = render_light(s, o, direction_from_angles_deg(20.0, 200.0), 5);
  }
  ASSERT_EQ(one.observed.size(), two.observed.size());
  EXPECT_TRUE(std::equal(one.observed.data(), one.observed.data() + one.observed.size(),
                         two.observed.data()));
  EXPECT_TRUE(
      std::equal(one.diffuse.data(), one.diffuse.data() + one.diffuse.size(), two.diffuse.data()));
  EXPECT_EQ(one.labels, two.labels);
}

// --- polynomial world ------------------------------------------------------------------------

TEST(SynthPolynomial, ImagesAreTheCoefficientsEvaluated) {
  const SynthOptions o = small_options("polynomial");
  const Scene s = build_scene(o);
  ASSERT_EQ(s.kind, SceneKind::kPolynomial);
  ASSERT_EQ(s.coefficients.model, ColourModel::kRGB);
  ASSERT_EQ(s.coefficients.width, 64);
  for (const Eigen::Vector3d& l : resolve_lights(o)) {
    const RenderedLight r = render_light(s, o, l, 0);
    for (int y = 0; y < s.height; ++y) {
      for (int x = 0; x < s.width; ++x) {
        double exact[3];
        evaluate_polynomial(s, x, y, l.x(), l.y(), exact);
        float map_rgb[3];
        s.coefficients.evaluate(x, y, l.x(), l.y(), map_rgb);
        for (int c = 0; c < 3; ++c) {
          ASSERT_NEAR(r.observed.at(x, y, c), exact[c], kFloatTol);
          ASSERT_NEAR(map_rgb[c], exact[c], kFloatTol);
          ASSERT_EQ(r.observed.at(x, y, c), r.diffuse.at(x, y, c));
        }
      }
    }
    EXPECT_EQ(std::count(r.labels.begin(), r.labels.end(), kLabelInlier),
              static_cast<long>(r.labels.size()));
  }
}

TEST(SynthPolynomial, ValuesStayInsideTheRangeOverTheHemisphere) {
  const SynthOptions o = small_options("polynomial", 32);
  const Scene s = build_scene(o);
  double lo = 1.0;
  double hi = 0.0;
  double spread = 0.0;  // the values do depend on the light
  for (int y = 0; y < s.height; y += 3) {
    for (int x = 0; x < s.width; x += 3) {
      double texel_lo = 1.0;
      double texel_hi = 0.0;
      for (int i = 0; i <= 12; ++i) {
        for (int j = 0; j < 36; ++j) {
          const double r = i / 12.0;  // includes the horizon, r = 1
          const double a = j * (2.0 * M_PI / 36.0);
          double rgb[3];
          evaluate_polynomial(s, x, y, r * std::cos(a), r * std::sin(a), rgb);
          for (double v : rgb) {
            texel_lo = std::min(texel_lo, v);
            texel_hi = std::max(texel_hi, v);
          }
        }
      }
      lo = std::min(lo, texel_lo);
      hi = std::max(hi, texel_hi);
      spread = std::max(spread, texel_hi - texel_lo);
    }
  }
  EXPECT_GE(lo, 0.05);
  EXPECT_LE(hi, 0.95);
  EXPECT_GT(spread, 0.3);
}

// --- options -------------------------------------------------------------------------------

TEST(SynthOptions, BadOptionsThrow) {
  auto expect_error = [](SynthOptions o, const std::string& fragment) {
    try {
      validate(o);
      (void)resolve_lights(o);
      ADD_FAILURE() << "no error for " << fragment;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
    }
  };
  SynthOptions o;
  o.width = 7;
  expect_error(o, "too small");
  o = {};
  o.light_dirs = {Eigen::Vector3d(1.0, 0.0, -0.1)};
  expect_error(o, "below the horizon");
  o = {};
  o.lights = "";
  expect_error(o, "no lights");
  o = {};
  o.lights = "dome48";
  expect_error(o, "unknown light layout");
  o = {};
  o.lights = "rings:95:4";
  expect_error(o, "");
  o = {};
  o.sensor.bits = 12;
  expect_error(o, "bit depth 12");
  o = {};
  o.sensor.bits = 32;
  expect_error(o, "png");
  o = {};
  o.sensor.file_type = FileType::kJpeg;
  o.sensor.bits = 16;
  expect_error(o, "jpg");
  o = {};
  o.sensor.noise_sigma_grey = -1.0;
  expect_error(o, "noise");
  o = {};
  o.sensor.exposure = 0.0;
  expect_error(o, "exposure");
  o = {};
  o.material.exponent = std::nan("");
  expect_error(o, "exponent");
  o = {};
  o.preset = "shiny";
  expect_error(o, "unknown preset");
  EXPECT_THROW((void)preset_options("shiny"), Error);
  EXPECT_THROW((void)parse_file_type("bmp"), Error);
  EXPECT_THROW((void)parse_scene_kind("sphere"), Error);
}

TEST(SynthOptions, BadOptionsWriteNothing) {
  ptmkit::test::ScratchDir dir;
  SynthOptions o = small_options();
  o.sensor.bits = 12;
  EXPECT_THROW((void)render_capture(o, dir / "out"), Error);
  EXPECT_FALSE(fs::exists(dir / "out"));
  o = small_options();
  o.lights = (dir / "missing.lp").string();
  EXPECT_THROW((void)render_capture(o, dir / "out"), Error);
  EXPECT_FALSE(fs::exists(dir / "out"));
}

TEST(SynthOptions, PresetsAndLightLayouts) {
  EXPECT_EQ(preset_options("matte").material.ks, 0.0);
  EXPECT_EQ(preset_options("glossy").material.ks, 0.8);
  EXPECT_EQ(preset_options("glossy").material.exponent, 100.0);
  EXPECT_EQ(preset_options("tall").relief.relief_height_frac,
            2.0 * preset_options("default").relief.relief_height_frac);
  EXPECT_EQ(preset_options("ambient").material.ambient, 0.1);
  EXPECT_EQ(preset_options("polynomial").sensor.file_type, FileType::kExr);
  SynthOptions o;
  EXPECT_EQ(resolve_lights(o).size(), 49u);
  o.lights = "icosa";
  EXPECT_EQ(resolve_lights(o).size(), 40u);
  o.lights = "rings:45:8,80:3:10";
  const auto dirs = resolve_lights(o);
  ASSERT_EQ(dirs.size(), 11u);
  EXPECT_NEAR(elevation_deg(dirs[0]), 45.0, 1e-9);

  ptmkit::test::ScratchDir dir;
  std::ofstream(dir / "l.lp") << "2\na.png 1 0 1\nb.png 0 1 1\n";
  o.lights = (dir / "l.lp").string();
  const auto from_lp = resolve_lights(o);
  ASSERT_EQ(from_lp.size(), 2u);
  EXPECT_NEAR(from_lp[1].y(), std::sqrt(0.5), 1e-12);
}

// --- capture folders -----------------------------------------------------------------------

TEST(SynthCapture, ByteIdenticalWhateverTheThreadCountAndOnReRuns) {
  ptmkit::test::ScratchDir dir;
  SynthOptions o = small_options("default", 48);
  o.lights = "rings:25:5,60:3";
  {
    ThreadLimit limit(1);
    (void)render_capture(o, dir / "one");
  }
  {
    ThreadLimit limit(2);
    (void)render_capture(o, dir / "two");
    (void)render_capture(o, dir / "two");  // re-run over the same folder
  }
  const auto files = all_files(dir / "one");
  ASSERT_EQ(files, all_files(dir / "two"));
  ASSERT_GT(files.size(), 8u * 3u);
  for (const auto& f : files) {
    EXPECT_EQ(read_bytes(dir / "one" / f), read_bytes(dir / "two" / f)) << f;
  }
}

TEST(SynthCapture, DefaultPresetWritesTheDocumentedTruth) {
  ptmkit::test::ScratchDir dir;
  const SynthOptions o = preset_options("default");  // the full 256x256, 49 lights
  const auto start = std::chrono::steady_clock::now();
  const SynthReport report = render_capture(o, dir.path());
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  RecordProperty("default_preset_seconds", std::to_string(seconds));
  EXPECT_EQ(report.images, 49);

  const LightSet lights = read_lp(dir / "lights.lp");
  ASSERT_EQ(lights.size(), 49u);
  EXPECT_EQ(lights.lights[0].image.filename(), "image_001.png");
  for (const auto& name :
       {"normals.exr", "normals.png", "albedo.exr", "albedo.png", "height.exr"}) {
    EXPECT_TRUE(fs::exists(dir.path() / "truth" / name)) << name;
  }
  const ImageInfo image = probe_image(dir / "image_049.png");
  EXPECT_EQ(image.width, 256);
  EXPECT_EQ(image.channels, 3);
  EXPECT_EQ(image.format, PixelFormat::kU8);
  EXPECT_EQ(image.colour_space, ColourSpace::kLinear);
  const ImageInfo labels = probe_image(dir.path() / "truth" / "labels" / "image_049.png");
  EXPECT_EQ(labels.channels, 1);
  EXPECT_EQ(labels.format, PixelFormat::kU8);
  EXPECT_EQ(probe_image(dir.path() / "truth" / "normals.png").format, PixelFormat::kU16);
  EXPECT_EQ(probe_image(dir.path() / "truth" / "diffuse" / "image_049.png").format,
            PixelFormat::kU8);

  // Files hold what the in-memory renderer gives.
  const Scene s = build_scene(o);
  const auto dirs = resolve_lights(o);
  const RenderedLight r = render_light(s, o, dirs[10], 10);
  const Image read = read_image(dir / "image_011.png");
  const Image read_diffuse = read_image(dir.path() / "truth" / "diffuse" / "image_011.png");
  const Image read_labels = read_image(dir.path() / "truth" / "labels" / "image_011.png");
  ASSERT_EQ(read.size(), r.observed.size());
  for (std::size_t i = 0; i < read.size(); ++i) {
    ASSERT_NEAR(read.data()[i], r.observed.data()[i], kFloatTol);
    ASSERT_NEAR(read_diffuse.data()[i], r.diffuse.data()[i], kFloatTol);
  }
  for (std::size_t i = 0; i < r.labels.size(); ++i) {
    ASSERT_EQ(std::lround(read_labels.data()[i] * 255.0f), r.labels[i]);
  }
  const Image normals = read_image(dir.path() / "truth" / "normals.exr");
  ASSERT_EQ(normals.channels(), 3);
  EXPECT_EQ(normals.at(17, 33, 2), s.normals.at(17, 33, 2));
  const Image height = read_image(dir.path() / "truth" / "height.exr");
  EXPECT_EQ(height.channels(), 1);
  EXPECT_EQ(height.at(100, 50, 0), s.height_at(100, 50));

  std::ifstream in(dir / "truth.json");
  const nlohmann::json j = nlohmann::json::parse(in);
  EXPECT_EQ(j["scene"], "relief");
  EXPECT_EQ(j["preset"], "default");
  EXPECT_EQ(j["seed"], o.seed);
  EXPECT_EQ(j["width"], 256);
  EXPECT_EQ(j["material"]["ks"], 0.3);
  EXPECT_EQ(j["material"]["exponent"], 40.0);
  EXPECT_EQ(j["sensor"]["bits"], 8);
  EXPECT_EQ(j["sensor"]["noise_sigma_grey"], 1.0);
  EXPECT_EQ(j["lights"]["count"], 49);
  ASSERT_EQ(j["images"].size(), 49u);
  EXPECT_EQ(j["images"][0]["file"], "image_001.png");
  EXPECT_EQ(j["images"][0]["labels"], "truth/labels/image_001.png");
  EXPECT_TRUE(j["labels"].contains("1"));
  EXPECT_TRUE(j["labels"].contains("2"));
}

TEST(SynthCapture, PolynomialPresetWritesItsCoefficients) {
  ptmkit::test::ScratchDir dir;
  SynthOptions o = small_options("polynomial", 24);
  o.lights = "rings:30:6,70:4";
  (void)render_capture(o, dir.path());
  const Image coeffs = read_image(dir.path() / "truth" / "coefficients.exr");
  ASSERT_EQ(coeffs.channels(), 18);
  const Scene s = build_scene(o);
  for (int y = 0; y < 24; y += 5) {
    for (int x = 0; x < 24; x += 5) {
      for (int k = 0; k < 18; ++k) {
        ASSERT_EQ(coeffs.at(x, y, k), s.coefficients.texel_coeffs(x, y)[k]);
      }
    }
  }
  const LightSet lights = read_lp(dir / "lights.lp");
  ASSERT_EQ(lights.size(), 10u);
  const Image img = read_image(lights.lights[3].image);
  EXPECT_EQ(lights.lights[3].image.extension(), ".exr");
  double rgb[3];
  const Eigen::Vector3d l = lights.lights[3].direction;
  evaluate_polynomial(s, 7, 9, l.x(), l.y(), rgb);
  // The .lp stores 9 significant digits of the direction.
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(img.at(7, 9, c), rgb[c], 1e-6);
  EXPECT_FALSE(fs::exists(dir.path() / "truth" / "normals.exr"));
}

TEST(SynthCapture, JpegWithoutTruth) {
  ptmkit::test::ScratchDir dir;
  SynthOptions o = small_options("default", 40);
  o.sensor.file_type = FileType::kJpeg;
  o.cast_shadows = false;
  o.write_truth = false;
  o.lights = "rings:40:3";
  const SynthReport report = render_capture(o, dir.path());
  EXPECT_EQ(report.files.size(), 4u);
  EXPECT_EQ(
      ptmkit::test::list_files(dir.path()),
      (std::vector<std::string>{"image_001.jpg", "image_002.jpg", "image_003.jpg", "lights.lp"}));
}

}  // namespace
}  // namespace ptmkit::synth
