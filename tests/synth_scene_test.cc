// Tests of the synth stage's scenes and cast shadows: relief maps, normals from slopes, seeds,
// shadow lengths and directions, and the time of a full capture's shadow masks.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "ptmkit/synth/synth.h"
#include "synth_test_util.h"
#include "tolerances.h"

namespace ptmkit::synth {
namespace {

using test::kFloatRoundoff;
using test::small_options;

// float32 heights of a few pixels (6.4 at the default relief on 64 px: rounding ~4e-7), with
// room.
constexpr double kHeightTolPx = 1e-4;
// Shadow edges: the bilinear ramp at the wall's foot starts one pixel before it.
constexpr double kShadowEdgePx = 1.0;
// A loose time bound that still catches a march that forgot to stop (minutes).
constexpr double kMaxShadowSeconds = 20.0;

// --- scenes -------------------------------------------------------------------------------

TEST(SynthScene, ReliefMapsAreInRange) {
  const SynthOptions o = small_options();
  const Scene s = build_scene(o);
  ASSERT_EQ(s.kind, SceneKind::kRelief);
  ASSERT_EQ(s.normals.width(), 64);
  const double max_height = o.relief.relief_height_frac * o.width;
  EXPECT_NEAR(s.max_height_px, max_height, kHeightTolPx);
  EXPECT_NEAR(*std::min_element(s.height_px.begin(), s.height_px.end()), 0.0, kFloatRoundoff);
  for (int y = 0; y < s.height; ++y) {
    for (int x = 0; x < s.width; ++x) {
      const Eigen::Vector3d n(s.normals.at(x, y, 0), s.normals.at(x, y, 1), s.normals.at(x, y, 2));
      ASSERT_NEAR(n.norm(), 1.0, kFloatRoundoff) << x << "," << y;
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
      for (int c = 0; c < 3; ++c) ASSERT_NEAR(s.normals.at(x, y, c), expected[c], kFloatRoundoff);
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
      if (d < length - kShadowEdgePx) {
        EXPECT_EQ(mask[y * kW + x], 1) << "elevation " << elevation << " x " << x;
      }
      if (d > length + kShadowEdgePx) {
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
  EXPECT_LT(seconds, kMaxShadowSeconds);
}

}  // namespace
}  // namespace ptmkit::synth
