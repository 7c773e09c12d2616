// Tests of the synth stage's rendering: Lambert shading through the sensor, labels against the
// images, noise, thread counts, and the polynomial world.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "ptmkit/core/colour.h"
#include "ptmkit/core/parallel.h"
#include "ptmkit/synth/synth.h"
#include "synth_test_util.h"
#include "tolerances.h"

namespace ptmkit::synth {
namespace {

using test::kFloatRoundoff;
using test::small_options;

// One grey level of 8-bit output, in normalised units.
constexpr double kGrey8 = 1.0 / 255.0;
// Half an 8-bit quantisation step: the sensor rounds to nearest.
constexpr double kHalfStep8Bit = 0.5 * kGrey8;
// 5 sigma of noise: exceeded with p ~ 6e-7 a sample, practically never over a test's samples.
constexpr double kNoiseSigmas = 5.0;
// Noise statistics of 49k samples at sigma 3 grey: the mean is good to about 0.014 grey
// (3 / sqrt(49k)) and the sd to about 1%; 0.1 grey is several times either.
constexpr double kNoiseStatTolGrey = 0.1;

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
          ASSERT_NEAR(r.diffuse.at(x, y, c), expected, kFloatRoundoff) << x << "," << y << "," << c;
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
    EXPECT_LE(brightest, 0.9 + kFloatRoundoff) << preset;
    EXPECT_GT(brightest, 0.75) << preset;
  }
}

TEST(SynthRender, LabelsAgreeWithTheImages) {
  const SynthOptions o = small_options("default");
  const Scene s = build_scene(o);
  const double sigma = o.sensor.noise_sigma_grey * kGrey8;
  // 5 sigma of noise plus half a grey level of quantisation.
  const double noise_tol = kNoiseSigmas * sigma + kHalfStep8Bit;
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
  EXPECT_NEAR(mean, 0.0, kNoiseStatTolGrey);
  EXPECT_NEAR(sd, std::sqrt(9.0 + 1.0 / 12.0), kNoiseStatTolGrey);
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
          ASSERT_NEAR(r.observed.at(x, y, c), exact[c], kFloatRoundoff);
          ASSERT_NEAR(map_rgb[c], exact[c], kFloatRoundoff);
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

}  // namespace
}  // namespace ptmkit::synth
