// Photo renders (synth/photo.h): truth consistency and every artefact's effect.
#include <algorithm>
#include <cmath>
#include <numbers>
#include <optional>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "ptmkit/core/colour.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/parallel.h"
#include "ptmkit/synth/photo.h"
#include "test_util.h"
#include "tolerances.h"

namespace {

using ptmkit::Image;
using ptmkit::synth::PhotoOptions;
using ptmkit::synth::PhotoRenderer;
using ptmkit::synth::PhotoTruth;
using V2 = Eigen::Vector2d;
using V3 = Eigen::Vector3d;
using ptmkit::test::kDoubleSolveRoundoff;

// The outline's axis angle from the conic in double, in degrees: rounding only.
constexpr double kAngleRoundoffDeg = 1e-6;
// A sphere 150 mm off the axis at 400 mm (f = 1000 px): its outline is longer along the line
// from the principal point (measured 3.4 px) and its centre lies beyond the centre's
// projection (measured 0.94 px).
constexpr double kOffAxisElongationPx = 0.5;
constexpr double kOffAxisCentreShiftPx = 0.5;
// A mask sampled at pixel centres against the ellipse: 1% of the area is a fifth of a pixel
// along the perimeter (~260 px); measured 0.05%.
constexpr double kMaskAreaRelTol = 0.01;
// The mask's centroid against the ellipse's centre: measured 0.021 px.
constexpr double kMaskCentroidTolPx = 0.05;
// The light's image is a disc about 0.2 px across, sampled every 1/16 px: its centroid is
// within about a sample spacing of the mirror point (measured 0.051 px).
constexpr double kMirrorPointTolPx = 0.07;
// The centroid of a highlight's saturated core against the mirror point: measured 0.080 px in
// chrome photographs with every artefact on, 0.25 px on the large sphere with flare.
constexpr double kPhotoCoreTolPx = 0.3;
// The flare shows: it changes some value by more than this (measured 0.18 or more).
constexpr double kFlareVisible = 0.1;
// The flare's streaks move the core's centroid by less than this: measured 0.006 px.
constexpr double kFlareCoreShiftPx = 0.05;
// The corners' loss of light against vignetting_corner_loss, averaged over a 12 x 12 patch:
// measured 0.029.
constexpr double kVignettingLossTol = 0.05;
// A pixel counts as changed by a switch when it moves by more than 2.5 grey levels (every
// switch changes 455 pixels or more so, against the 20 required).
constexpr float kChangedPixel = 2.5f / 255.0f;
// The surface reflection of the light on glass is plainly there: half of full scale or more
// (measured 1.96 or more).
constexpr double kVisibleReflection = 0.5;
// Linear full scale: brighter values clip in the photograph.
constexpr double kClipLevel = 1.0;
// The coin's glint changes a pixel by half of full scale or more (measured 1.27).
constexpr double kCoinGlint = 0.5;
// photo-large-sphere: one sphere of about 180 px radius (docs/CALIBRATION.md; measured
// 180.4 px), cut by the top edge (measured 0.81 of its outline inside the frame) and
// hidden by its pedestal below (measured 0.62 visible).
constexpr double kLargeSphereMinRadiusPx = 150.0;
constexpr double kLargeSphereMaxInsideFrame = 0.97;
constexpr double kPedestalMinHidden = 0.05;
constexpr double kLargeSphereMinVisible = 0.5;
// The coin at 320 x 180 px: measured radius 19.2 px.
constexpr double kSmallCoinMinRadiusPx = 5.0;

PhotoOptions small(const char* preset, const char* lights) {
  PhotoOptions o = ptmkit::synth::photo_preset_options(preset);
  ptmkit::synth::resize_photo(320, 180, &o);
  o.lights = lights;
  return o;
}

double green(const Image& im, int x, int y) { return im.at(x, y, 1); }

// Centroid of max(a - b, 0) over a (2 r + 1)^2 window around the largest difference inside
// `mask` (1 = the sphere).
V2 difference_centroid(const Image& a, const Image& b, const Image& mask, int r = 5) {
  double best = -1.0;
  int bx = 0, by = 0;
  for (int y = 0; y < a.height(); ++y) {
    for (int x = 0; x < a.width(); ++x) {
      if (mask.at(x, y, 0) < 0.5f) continue;
      const double d = green(a, x, y) - green(b, x, y);
      if (d > best) {
        best = d;
        bx = x;
        by = y;
      }
    }
  }
  double sw = 0.0, sx = 0.0, sy = 0.0;
  for (int y = std::max(by - r, 0); y <= std::min(by + r, a.height() - 1); ++y) {
    for (int x = std::max(bx - r, 0); x <= std::min(bx + r, a.width() - 1); ++x) {
      const double d = std::max(green(a, x, y) - green(b, x, y), 0.0);
      sw += d;
      sx += d * x;
      sy += d * y;
    }
  }
  return {sx / sw, sy / sw};
}

double max_abs_difference(const Image& a, const Image& b) {
  double m = 0.0;
  for (std::size_t i = 0; i < static_cast<std::size_t>(a.width()) * a.height() * 3; ++i) {
    m = std::max(m, static_cast<double>(std::abs(a.data()[i] - b.data()[i])));
  }
  return m;
}

TEST(SynthPhoto, OutlineOfASphereOnTheAxisIsItsCircle) {
  const V2 pp(319.5, 179.5);
  const auto on = ptmkit::synth::sphere_outline(V3(0, 0, 400), 20.0, 1000.0, pp);
  const double r = 1000.0 * 20.0 / std::sqrt(400.0 * 400.0 - 20.0 * 20.0);
  EXPECT_NEAR(on.semi_major_px, r, kDoubleSolveRoundoff);
  EXPECT_NEAR(on.semi_minor_px, r, kDoubleSolveRoundoff);
  EXPECT_NEAR((on.centre_px - pp).norm(), 0.0, kDoubleSolveRoundoff);
  // Off the axis: an ellipse elongated along the line from the principal point, its centre
  // beyond the centre's projection.
  const auto off = ptmkit::synth::sphere_outline(V3(150, 0, 400), 20.0, 1000.0, pp);
  EXPECT_GT(off.semi_major_px, off.semi_minor_px + kOffAxisElongationPx);
  EXPECT_NEAR(std::min(off.angle_deg, 180.0 - off.angle_deg), 0.0, kAngleRoundoffDeg);
  EXPECT_GT(off.centre_px.x(), off.centre_projection_px.x() + kOffAxisCentreShiftPx);
  EXPECT_NEAR(off.centre_px.y(), pp.y(), kDoubleSolveRoundoff);
}

TEST(SynthPhoto, MasksMatchTheTruthOutline) {
  PhotoOptions o = ptmkit::synth::photo_preset_options("photo-chrome");
  o.lights = "rings:45:1";
  const PhotoRenderer renderer(o);
  const PhotoTruth& truth = renderer.truth();
  ASSERT_EQ(truth.spheres.size(), 2u);
  for (int k = 0; k < 2; ++k) {
    const auto& t = truth.spheres[static_cast<std::size_t>(k)];
    EXPECT_EQ(t.outline_inside_frame, 1.0);
    EXPECT_EQ(t.outline_visible, 1.0);  // the cups are under the spheres, seen from above
    const Image mask = renderer.sphere_mask(k);
    double n = 0.0, mx = 0.0, my = 0.0;
    for (int y = 0; y < mask.height(); ++y) {
      for (int x = 0; x < mask.width(); ++x) {
        if (mask.at(x, y, 0) < 0.5f) continue;
        n += 1.0;
        mx += x;
        my += y;
      }
    }
    const double area = std::numbers::pi * t.outline.semi_major_px * t.outline.semi_minor_px;
    EXPECT_NEAR(n, area, kMaskAreaRelTol * area);
    EXPECT_NEAR(mx / n, t.outline.centre_px.x(), kMaskCentroidTolPx);
    EXPECT_NEAR(my / n, t.outline.centre_px.y(), kMaskCentroidTolPx);
  }
}

// Centroid of max(a - b - half the peak, 0) in a (2 r + 1)^2 window around `near`: the core
// of a highlight, whatever symmetric glow surrounds it.
V2 core_centroid(const Image& a, const Image* b, const V2& near, int r, bool linearise) {
  auto value = [&](int x, int y) {
    double v = green(a, x, y), w = b != nullptr ? green(*b, x, y) : 0.0;
    if (linearise) {
      v = ptmkit::srgb_to_linear(v);
      w = b != nullptr ? ptmkit::srgb_to_linear(w) : 0.0;
    }
    return v - w;
  };
  const int cx = static_cast<int>(std::lround(near.x())),
            cy = static_cast<int>(std::lround(near.y()));
  double peak = 0.0;
  for (int y = cy - r; y <= cy + r; ++y)
    for (int x = cx - r; x <= cx + r; ++x) peak = std::max(peak, value(x, y));
  double sw = 0.0, sx = 0.0, sy = 0.0;
  for (int y = cy - r; y <= cy + r; ++y) {
    for (int x = cx - r; x <= cx + r; ++x) {
      const double v = value(x, y) - 0.5 * peak;
      if (v <= 0.0) continue;
      sw += v;
      sx += v * x;
      sy += v * y;
    }
  }
  return {sx / sw, sy / sw};
}

TEST(SynthPhoto, ChromeHighlightsLieWhereMirrorGeometryPutsThem) {
  PTMKIT_RELEASE_BUILD_ONLY();
  // Without the lens's spread: the light's image on the sphere (the difference of two
  // images whose highlights are far apart) centred on the truth to a few hundredths.
  PhotoOptions o = ptmkit::synth::photo_preset_options("photo-chrome");
  o.lights = "rings:25:4,55:4";
  PhotoOptions clean = o;
  clean.artefacts.flare = false;
  clean.artefacts.bloom = false;
  // The photographs: every lens and sensor artefact, but no windows or lamps (their
  // reflections saturate in chrome, and where both images clip, a difference shows nothing).
  PhotoOptions photo_options = o;
  photo_options.windows = 0;
  photo_options.lamps = 0;
  const PhotoRenderer renderer(clean), photographer(photo_options);
  const PhotoTruth& truth = renderer.truth();
  const int n = static_cast<int>(truth.light_dirs.size());
  std::vector<Image> radiance, photo;
  for (int i = 0; i < n; ++i) {
    radiance.push_back(renderer.render_radiance(i));
    photo.push_back(photographer.render(i));
  }
  int checked = 0;
  for (int k = 0; k < 2; ++k) {
    const Image mask = renderer.sphere_mask(k);
    for (int i = 0; i < n; ++i) {
      const auto& hl =
          truth.spheres[static_cast<std::size_t>(k)].highlight_px[static_cast<std::size_t>(i)];
      if (!hl) continue;
      // The light of the same ring opposite in azimuth: its highlight is across the sphere.
      const auto j = static_cast<std::size_t>((i / 4) * 4 + (i % 4 + 2) % 4);
      const Image& other = radiance[j];
      const V2 c = difference_centroid(radiance[static_cast<std::size_t>(i)], other, mask);
      EXPECT_NEAR(c.x(), hl->x(), kMirrorPointTolPx) << "sphere " << k << " light " << i;
      EXPECT_NEAR(c.y(), hl->y(), kMirrorPointTolPx) << "sphere " << k << " light " << i;
      // The photographs, every artefact on (bloom, flare, vignetting, noise, clipping, sRGB):
      // the saturated core.
      const V2 p = core_centroid(photo[static_cast<std::size_t>(i)], &photo[j], *hl, 9, true);
      EXPECT_NEAR((p - *hl).norm(), 0.0, kPhotoCoreTolPx) << "sphere " << k << " light " << i;
      ++checked;
    }
  }
  EXPECT_GE(checked, 12);
}

TEST(SynthPhoto, FlareDoesNotMoveTheBrightestCore) {
  PhotoOptions o = small("photo-large-sphere", "rings:45:4:0");
  o.artefacts.noise = false;
  PhotoOptions no_flare = o;
  no_flare.artefacts.flare = false;
  const PhotoRenderer with(o), without(no_flare);
  int checked = 0;
  for (int i = 0; i < 4; ++i) {
    const auto& hl = with.truth().spheres[0].highlight_px[static_cast<std::size_t>(i)];
    if (!hl) continue;
    const Image a = with.render_radiance(i), b = without.render_radiance(i);
    EXPECT_GT(max_abs_difference(a, b), kFlareVisible) << "the flare shows";
    // Centroid of the light above half of the core's peak, with and without the streaks.
    auto centroid = [&](const Image& im) { return core_centroid(im, nullptr, *hl, 3, false); };
    EXPECT_LT((centroid(a) - centroid(b)).norm(), kFlareCoreShiftPx) << "light " << i;
    EXPECT_LT((centroid(a) - *hl).norm(), kPhotoCoreTolPx) << "light " << i;
    ++checked;
  }
  EXPECT_GE(checked, 3);
}

TEST(SynthPhoto, VignettingOffKeepsTheCentre) {
  PhotoOptions o = small("photo-dome", "rings:40:2");
  o.artefacts.flare = false;
  o.artefacts.bloom = false;
  PhotoOptions off = o;
  off.artefacts.vignetting = false;
  const Image a = PhotoRenderer(o).render(0), b = PhotoRenderer(off).render(0);
  // Untouched within 10% of the half-diagonal (18 px here).
  for (int y = 80; y < 100; ++y) {
    for (int x = 150; x < 170; ++x) {
      for (int c = 0; c < 3; ++c) ASSERT_EQ(a.at(x, y, c), b.at(x, y, c)) << x << "," << y;
    }
  }
  // The corners lose about vignetting_corner_loss of their light (linear; the images are
  // sRGB, the noise averages out over the patch).
  double sa = 0.0, sb = 0.0;
  for (int y = 0; y < 12; ++y) {
    for (int x = 0; x < 12; ++x) {
      sa += ptmkit::srgb_to_linear(a.at(x, y, 1));
      sb += ptmkit::srgb_to_linear(b.at(x, y, 1));
    }
  }
  EXPECT_NEAR(sa / sb, 1.0 - o.artefacts.vignetting_corner_loss, kVignettingLossTol);
}

TEST(SynthPhoto, EveryArtefactSwitchChangesTheImage) {
  // Chrome: its highlights saturate at this size, so the flare and bloom show.
  const PhotoOptions base = small("photo-chrome", "rings:40:2");
  const Image reference = PhotoRenderer(base).render(0);
  struct Case {
    const char* name;
    void (*change)(PhotoOptions*);
  };
  const Case cases[] = {
      {"flare off", [](PhotoOptions* o) { o->artefacts.flare = false; }},
      {"bloom off", [](PhotoOptions* o) { o->artefacts.bloom = false; }},
      {"vignetting off", [](PhotoOptions* o) { o->artefacts.vignetting = false; }},
      {"noise off", [](PhotoOptions* o) { o->artefacts.noise = false; }},
      {"no bases", [](PhotoOptions* o) { o->sphere_bases = false; }},
      {"no object", [](PhotoOptions* o) { o->object = false; }},
      {"room only in reflections", [](PhotoOptions* o) { o->reflect_scene = false; }},
      {"no distractor", [](PhotoOptions* o) { o->distractor = ptmkit::synth::Distractor::kNone; }},
      {"coin", [](PhotoOptions* o) { o->distractor = ptmkit::synth::Distractor::kCoin; }},
      {"lit room", [](PhotoOptions* o) { o->environment = ptmkit::synth::PhotoEnvironment::kLit; }},
      {"no windows", [](PhotoOptions* o) { o->windows = 0; }},
      {"no lamps", [](PhotoOptions* o) { o->lamps = 0; }},
      {"black glossy",
       [](PhotoOptions* o) {
         for (auto& s : o->spheres) s.material = ptmkit::synth::SphereMaterial::kBlackGlossy;
       }},
      {"glass",
       [](PhotoOptions* o) {
         for (auto& s : o->spheres) s.material = ptmkit::synth::SphereMaterial::kGlass;
       }},
      {"linear", [](PhotoOptions* o) { o->srgb = false; }},
      {"exposure jitter", [](PhotoOptions* o) { o->artefacts.exposure_jitter_ev = 1.0; }},
      {"shake", [](PhotoOptions* o) { o->artefacts.shake_px = 2.0; }},
  };
  for (const Case& c : cases) {
    PhotoOptions o = base;
    c.change(&o);
    const Image im = PhotoRenderer(o).render(0);
    int changed = 0;
    for (std::size_t i = 0; i < static_cast<std::size_t>(im.width()) * im.height() * 3; ++i) {
      if (std::abs(im.data()[i] - reference.data()[i]) > kChangedPixel) ++changed;
    }
    EXPECT_GT(changed, 20) << c.name;
  }
}

// Exposure jitter scales each image's radiance by one factor (different from image to
// image, 2^u with |u| <= the jitter); shake moves each image's content by a vector no longer
// than shake_px, different from image to image.
TEST(SynthPhoto, ExposureJitterScalesEachImageAndShakeShiftsIt) {
  PhotoOptions o = small("photo-dome", "rings:40:4");
  o.artefacts.flare = false;
  o.artefacts.bloom = false;
  o.artefacts.vignetting = false;
  PhotoOptions jit = o;
  jit.artefacts.exposure_jitter_ev = 1.0;
  const PhotoRenderer plain(o), jittered(jit);
  std::vector<double> factors;
  for (int i = 0; i < 4; ++i) {
    const Image a = plain.render_radiance(i), b = jittered.render_radiance(i);
    std::vector<double> ratio;
    for (std::size_t k = 0; k < static_cast<std::size_t>(a.width()) * a.height() * 3; ++k) {
      const double va = a.data()[k], vb = b.data()[k];
      if (va < 0.02 || va > 0.4 || vb > 0.9) continue;  // lit, far from the clip
      ratio.push_back(vb / va);
    }
    ASSERT_GT(ratio.size(), 1000u) << "image " << i;
    std::vector<double> sorted = ratio;
    std::nth_element(sorted.begin(),
                     sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2), sorted.end());
    const double f = sorted[sorted.size() / 2];
    // Pixels beside a saturated sample are sampled more finely where the jitter makes it
    // saturate (or not): those few differ by more than the factor.
    const auto same = std::count_if(ratio.begin(), ratio.end(),
                                    [&](double r) { return std::abs(r - f) <= 1e-3 * f; });
    EXPECT_GE(static_cast<double>(same), 0.98 * static_cast<double>(ratio.size()))
        << "one factor over image " << i;
    EXPECT_GE(f, 0.5 - 1e-6);
    EXPECT_LE(f, 2.0 + 1e-6);
    factors.push_back(f);
  }
  EXPECT_GT(*std::max_element(factors.begin(), factors.end()) -
                *std::min_element(factors.begin(), factors.end()),
            0.05)
      << "the factor differs from image to image";

  PhotoOptions shaken = o;
  shaken.artefacts.shake_px = 1.5;
  const PhotoRenderer moved(shaken);
  std::vector<Eigen::Vector2d> shifts;
  for (int i = 0; i < 4; ++i) {
    const auto& hl = plain.truth().spheres[0].highlight_px[static_cast<std::size_t>(i)];
    if (!hl) continue;
    const Image a = plain.render_radiance(i), b = moved.render_radiance(i);
    const Eigen::Vector2d d =
        core_centroid(b, nullptr, *hl, 6, false) - core_centroid(a, nullptr, *hl, 6, false);
    EXPECT_LE(d.norm(), 1.5 + 0.1) << "image " << i;
    shifts.push_back(d);
  }
  ASSERT_GE(shifts.size(), 3u);
  EXPECT_GT((shifts[0] - shifts[1]).norm() + (shifts[1] - shifts[2]).norm(), 0.1)
      << "the shift differs from image to image";
}

TEST(SynthPhoto, DeterministicWhateverTheThreadCount) {
  const PhotoOptions o = small("photo-glass", "rings:50:3");
  const Image a = PhotoRenderer(o).render(1);
  const Image b = PhotoRenderer(o).render(1);
  Image c;
  {
    ptmkit::ThreadLimit one(1);
    c = PhotoRenderer(o).render(1);
  }
  EXPECT_EQ(max_abs_difference(a, b), 0.0);
  EXPECT_EQ(max_abs_difference(a, c), 0.0);
  PhotoOptions other = o;
  other.seed = 2;
  EXPECT_GT(max_abs_difference(a, PhotoRenderer(other).render(1)), 0.0);
}

TEST(SynthPhoto, ReflectionsOfTheRoomAndSceneAreStatic) {
  // A chrome sphere shows nothing but reflections: away from the two lights' highlights, two
  // images are identical (bloom, flare and noise off).
  PhotoOptions o = small("photo-chrome", "rings:30:2,60:2");
  o.artefacts.flare = false;
  o.artefacts.bloom = false;
  o.artefacts.noise = false;
  const PhotoRenderer renderer(o);
  const Image a = renderer.render_radiance(0), b = renderer.render_radiance(3);
  const Image mask = renderer.sphere_mask(0);
  const auto& t = renderer.truth().spheres[0];
  int compared = 0;
  for (int y = 0; y < a.height(); ++y) {
    for (int x = 0; x < a.width(); ++x) {
      // Pixels wholly on the sphere (an outline pixel also sees the ground, lit by the light).
      bool inside = true;
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx)
          if (mask.at(std::clamp(x + dx, 0, a.width() - 1), std::clamp(y + dy, 0, a.height() - 1),
                      0) < 0.5f)
            inside = false;
      if (!inside) continue;
      bool near = false;
      for (int i : {0, 3}) {
        const auto& h = t.highlight_px[static_cast<std::size_t>(i)];
        if (h && (V2(x, y) - *h).norm() < 6.0) near = true;
      }
      if (near) continue;
      for (int c = 0; c < 3; ++c) ASSERT_EQ(a.at(x, y, c), b.at(x, y, c)) << x << "," << y;
      ++compared;
    }
  }
  EXPECT_GT(compared, 1000);
}

TEST(SynthPhoto, GlassShowsAHotSpotThatIsNoMirrorReflection) {
  PTMKIT_RELEASE_BUILD_ONLY();
  PhotoOptions o = ptmkit::synth::photo_preset_options("photo-glass");
  o.lights = "rings:60:4:10";
  o.artefacts.flare = false;
  o.artefacts.bloom = false;
  o.artefacts.noise = false;
  // The light's own contribution: the same light twice as strong, minus it (the room's part
  // cancels).
  PhotoOptions brighter = o;
  brighter.light_irradiance *= 2.0;
  const PhotoRenderer renderer(o), doubled(brighter);
  const auto& truth = renderer.truth();
  int hot_spots = 0, checked = 0;
  for (int k = 0; k < 2; ++k) {
    const Image mask = renderer.sphere_mask(k);
    const auto& t = truth.spheres[static_cast<std::size_t>(k)];
    for (int i = 0; i < 4; ++i) {
      const auto& hl = t.highlight_px[static_cast<std::size_t>(i)];
      if (!hl) continue;  // the camera hides the light from this sphere
      ++checked;
      const Image a = doubled.render_radiance(i), b = renderer.render_radiance(i);
      double far_peak = 0.0, mirror_peak = 0.0;
      for (int y = 0; y < a.height(); ++y) {
        for (int x = 0; x < a.width(); ++x) {
          if (mask.at(x, y, 0) < 0.5f) continue;
          const double d = green(a, x, y) - green(b, x, y);
          const double dist = (V2(x, y) - *hl).norm();
          if (dist > 0.4 * t.outline.radius_px) far_peak = std::max(far_peak, d);
          if (dist < 2.0) mirror_peak = std::max(mirror_peak, d);
        }
      }
      EXPECT_GT(mirror_peak, kVisibleReflection)
          << "the surface reflection, sphere " << k << " light " << i;
      // A spot away from the mirror point that saturates the sensor, as the reflection does:
      // in the photograph both are clipped cores.
      EXPECT_GT(mirror_peak, kClipLevel);
      if (far_peak > kClipLevel) ++hot_spots;
    }
  }
  EXPECT_GE(checked, 6);
  // The spot shows where the eye ray's path in the glass meets the focused beam: for about
  // half of these lights.
  EXPECT_GE(2 * hot_spots, checked);
}

TEST(SynthPhoto, TheCoinGlintsWithTheLight) {
  const PhotoOptions o = small("photo-dome", "rings:20:6");
  const PhotoRenderer renderer(o);
  const auto& t = renderer.truth();
  ASSERT_GT(t.distractor_radius_px, kSmallCoinMinRadiusPx);
  double strongest = 0.0;
  for (int i = 0; i < 3; ++i) {
    const Image a = renderer.render_radiance(i), b = renderer.render_radiance(i + 3);
    for (int y = 0; y < a.height(); ++y) {
      for (int x = 0; x < a.width(); ++x) {
        if ((V2(x, y) - t.distractor_centre_px).norm() > t.distractor_radius_px - 1.0) continue;
        strongest = std::max(strongest, std::abs(green(a, x, y) - green(b, x, y)));
      }
    }
  }
  EXPECT_GT(strongest, kCoinGlint);
}

TEST(SynthPhoto, LargeSphereIsCutByTheFrameAndHiddenByItsBase) {
  const PhotoRenderer renderer(ptmkit::synth::photo_preset_options("photo-large-sphere"));
  const auto& t = renderer.truth().spheres[0];
  EXPECT_GT(t.outline.radius_px, kLargeSphereMinRadiusPx);
  EXPECT_LT(t.outline_inside_frame, kLargeSphereMaxInsideFrame);
  EXPECT_LT(t.outline_visible, t.outline_inside_frame - kPedestalMinHidden);
  EXPECT_GT(t.outline_visible, kLargeSphereMinVisible);
}

TEST(SynthPhoto, BadOptionsAreRefused) {
  PhotoOptions o = ptmkit::synth::photo_preset_options("photo-dome");
  o.artefacts.flare_spokes = 5;
  EXPECT_THROW(PhotoRenderer{o}, ptmkit::Error);
  o = ptmkit::synth::photo_preset_options("photo-dome");
  o.spheres[1].centre_mm = o.spheres[0].centre_mm;
  EXPECT_THROW(PhotoRenderer{o}, ptmkit::Error);
  o = ptmkit::synth::photo_preset_options("photo-dome");
  o.focal_px = std::nan("");
  EXPECT_THROW(PhotoRenderer{o}, ptmkit::Error);
  EXPECT_THROW((void)ptmkit::synth::photo_preset_options("photo-nothing"), ptmkit::Error);
  EXPECT_THROW((void)ptmkit::synth::parse_sphere_material("wood"), ptmkit::Error);
  o = ptmkit::synth::photo_preset_options("photo-dome");
  EXPECT_THROW(ptmkit::synth::resize_photo(320, 320, &o), ptmkit::Error);
  o = ptmkit::synth::photo_preset_options("photo-dome");
  o.artefacts.exposure_jitter_ev = -0.5;
  EXPECT_THROW(PhotoRenderer{o}, ptmkit::Error);
  o = ptmkit::synth::photo_preset_options("photo-dome");
  o.artefacts.shake_px = std::nan("");
  EXPECT_THROW(PhotoRenderer{o}, ptmkit::Error);
}

}  // namespace
