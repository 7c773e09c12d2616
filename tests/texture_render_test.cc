// Rendering onto geometry: head-on plane equals relight, perspective-correct texture
// coordinates against the analytic ray-plane intersection, and no aliasing blow-up at grazing
// views against a supersampled reference.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include <Eigen/Geometry>
#include <random>

#include "ptmkit/core/light_layout.h"
#include "ptmkit/texture/filtering.h"
#include "ptmkit/texture/integer_model.h"
#include "ptmkit/texture/ptm8.h"
#include "ptmkit/texture/relight.h"
#include "ptmkit/texture/render.h"
#include "test_util.h"
#include "tolerances.h"

namespace ptmkit::texture {
namespace {

using test::kDoubleSolveRoundoff;
using test::kFloatSumRoundoff;

// Perspective-correct texture coordinates written to a float image against the ray-plane
// intersection in double: measured worst 3e-8.
constexpr double kTexcoordTol = 1e-5;
// The automatic filter against bilinear level-0 sampling of the grazing checkerboard, RMSE
// ratio: measured 0.021 / 0.072 = 0.29 (docs/TEXTURE.md).
constexpr double kAutoOverPointRmseRatio = 0.5;
// RMSE ceiling of the automatic filter: measured 0.021 (docs/TEXTURE.md), bounded at about
// six times that; the ratio to point sampling is the sharper check.
constexpr double kAutoFilterRmseCeiling = 0.12;

CoefficientMap random_map(int w, int h, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  CoefficientMap map(w, h, ColourModel::kRGB);
  for (std::size_t j = 0; j < map.coeffs.size(); ++j)
    map.coeffs[j] = static_cast<float>(j % kPtmTerms == 5 ? 0.5 + 0.3 * u(rng) : 0.2 * u(rng));
  return map;
}

RenderOptions head_on(int w, int h) {
  RenderOptions o;
  o.camera.width = w;
  o.camera.height = h;
  o.camera.ortho_height = static_cast<double>(h) / std::max(w, h);
  o.tessellation = 1;
  return o;
}

TEST(TextureRender, HeadOnOrthographicPlaneEqualsRelight) {
  const CoefficientMap map = random_map(24, 16, test::test_seed());
  for (const Eigen::Vector3d& l : {Eigen::Vector3d(0, 0, 1), direction_from_angles_deg(30, 70)}) {
    RenderOptions o = head_on(24, 16);
    o.light_dir = l;
    RenderReport rep;
    const Image r = render_texture(map, o, &rep);
    const Image ref = relight(map, l);
    EXPECT_EQ(rep.covered, 24u * 16u);
    EXPECT_NEAR(rep.mean_lod, 0.0, kDoubleSolveRoundoff);
    for (std::size_t i = 0; i < r.size(); ++i)
      ASSERT_NEAR(r.data()[i], ref.data()[i], kFloatSumRoundoff) << i;
    o.integer = true;
    const Image ri = render_texture(map, o);
    const Image refi = relight_integer(quantise_ptm8(map), l);
    for (std::size_t i = 0; i < ri.size(); ++i) ASSERT_EQ(ri.data()[i], refi.data()[i]) << i;
  }
}

TEST(TextureRender, PerspectiveCorrectTexCoordsMatchTheRayPlaneIntersection) {
  const CoefficientMap map = random_map(32, 32, 1);
  RenderOptions o;
  o.tessellation = 1;  // two big triangles: affine interpolation would be far off
  o.output_texcoords = true;
  o.camera.position = {0.2, -1.2, 0.9};
  o.camera.target = {0.0, 0.1, 0.0};
  o.camera.fov_y_deg = 60.0;
  o.camera.width = o.camera.height = 64;
  const Image r = render_texture(map, o);
  const RenderCamera& c = o.camera;
  const Eigen::Vector3d f = (c.target - c.position).normalized();
  const Eigen::Vector3d rt = f.cross(c.up).normalized(), up = rt.cross(f);
  const double focal = 0.5 * c.height / std::tan(0.5 * c.fov_y_deg * std::numbers::pi / 180.0);
  int checked = 0;
  double worst = 0.0;
  for (int y = 0; y < c.height; ++y)
    for (int x = 0; x < c.width; ++x) {
      const Eigen::Vector3d ray =
          (f + (x + 0.5 - 0.5 * c.width) / focal * rt - (y + 0.5 - 0.5 * c.height) / focal * up);
      const double t = -c.position.z() / ray.z();
      if (!(t > 0)) continue;
      const Eigen::Vector3d p = c.position + t * ray;
      const double u = p.x() + 0.5, v = p.y() + 0.5;
      if (u < 0.01 || u > 0.99 || v < 0.01 || v > 0.99) continue;  // clear of the edges
      worst = std::max({worst, std::abs(r.at(x, y, 0) - u), std::abs(r.at(x, y, 1) - v)});
      ++checked;
    }
  EXPECT_GT(checked, 500);
  EXPECT_LT(worst, kTexcoordTol);
}

TEST(TextureRender, GrazingViewDoesNotAliasAgainstASupersampledReference) {
  // A texel checkerboard: point sampling a minified view of it aliases badly.
  CoefficientMap map(128, 128, ColourModel::kRGB);
  for (int y = 0; y < 128; ++y)
    for (int x = 0; x < 128; ++x)
      for (int p = 0; p < 3; ++p)
        map.texel_coeffs(x, y)[p * kPtmTerms + 5] = (x + y) % 2 ? 0.9f : 0.1f;
  RenderOptions o;
  o.camera.position = {0.0, -1.0, 0.18};
  o.camera.target = {0.0, 0.2, 0.0};
  o.camera.fov_y_deg = 40.0;
  o.camera.width = o.camera.height = 48;
  o.tessellation = 8;
  RenderOptions big = o;
  big.camera.width = big.camera.height = 48 * 8;
  big.filter = RenderFilter::kBilinear;
  Image ref = render_texture(map, big);
  for (int k = 0; k < 3; ++k) ref = downsample_box(ref);
  auto rmse = [&](const Image& a) {
    double s = 0;
    for (std::size_t i = 0; i < a.size(); ++i) s += std::pow(a.data()[i] - ref.data()[i], 2);
    return std::sqrt(s / static_cast<double>(a.size()));
  };
  RenderOptions point = o;
  point.filter = RenderFilter::kBilinear;
  RenderReport rep;
  const double e_auto = rmse(render_texture(map, o, &rep));
  const double e_point = rmse(render_texture(map, point));
  std::printf(
      "grazing checkerboard: RMSE vs 8x8 supersampled: auto filter %.4f (%zu trilinear, "
      "%zu summed-area), bilinear level 0 %.4f\n",
      e_auto, rep.trilinear, rep.sat, e_point);
  EXPECT_GT(rep.sat, 0u);
  EXPECT_LT(e_auto, kAutoOverPointRmseRatio * e_point);
  EXPECT_LT(e_auto, kAutoFilterRmseCeiling);
}

TEST(TextureRender, LightBehindTheSurfaceIsBlackAndShapesRender) {
  const CoefficientMap map = random_map(16, 16, 3);
  for (Geometry g : {Geometry::kPlane, Geometry::kCylinder, Geometry::kSphere}) {
    RenderOptions o;
    o.geometry = g;
    o.camera.width = o.camera.height = 32;
    o.tessellation = 16;
    o.light_dir = {0, 0, -1};
    RenderReport rep;
    const Image r = render_texture(map, o, &rep);
    EXPECT_GT(rep.covered, 100u);
    if (g == Geometry::kPlane) {
      for (std::size_t i = 0; i < r.size(); ++i) EXPECT_EQ(r.data()[i], 0.0f);
    }
    o.shading = RenderShading::kLuminance;
    o.light_dir = {0.3, 0.2, 1};
    (void)render_texture(map, o);
    o.shading = RenderShading::kPhongTexture;
    (void)render_texture(map, o);
  }
}

// A YCC texture (one luminance polynomial, constant chroma) renders exactly as its RGB form
// through every filter, including the summed-area path, whose table holds the RGB form.
TEST(TextureRender, YccTextureRendersAsItsRgbFormThroughEveryFilter) {
  const CoefficientMap ycc = to_luminance_polynomial(random_map(16, 16, test::test_seed()));
  ASSERT_EQ(ycc.model, ColourModel::kYCC);
  const CoefficientMap rgb = to_rgb_polynomials(ycc);
  for (RenderFilter f : {RenderFilter::kSat, RenderFilter::kTrilinear, RenderFilter::kAuto}) {
    RenderOptions o;
    o.geometry = Geometry::kPlane;
    o.camera.width = o.camera.height = 24;
    o.camera.position = {0.0, -2.0, 0.6};  // grazing: anisotropic footprints
    o.camera.fov_y_deg = 40.0;
    o.filter = f;
    o.light_dir = {0.3, 0.2, 1.0};
    const Image a = render_texture(ycc, o);
    const Image b = render_texture(rgb, o);
    for (std::size_t i = 0; i < a.size(); ++i)
      ASSERT_NEAR(a.data()[i], b.data()[i], kFloatSumRoundoff) << i;
  }
}

}  // namespace
}  // namespace ptmkit::texture
