// The fit pipeline as one path for every basis and source: images in memory follow the files'
// channel rule, every basis goes through the same sink interface, sinks refuse layouts they
// cannot store, and `ptmkit fit` commits its outputs together.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <string>
#include <vector>

#include "ptmkit/core/atomic_file.h"
#include "ptmkit/core/coefficients.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/light_layout.h"
#include "ptmkit/core/stack_reader.h"
#include "ptmkit/fit/fit.h"
#include "ptmkit/fit/plan.h"
#include "ptmkit/texture/ptm.h"
#include "ptmkit/texture/rti.h"
#include "test_util.h"

namespace ptmkit {
namespace {

// The channels of a texel relit from a colourful scene differ by more than this; a grey fit
// leaves them equal, or apart by float rounding (1e-7).
constexpr double kColourfulMinSpread = 1e-3;

using test::ScratchDir;

std::string read_bytes(const std::filesystem::path& p) {
  std::ifstream f(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>()};
}

// A colourful capture in memory: per texel and channel a smooth function of the light, with
// `channels` channels (4: an alpha channel of its own values, which must not be fitted).
std::vector<Image> capture(const std::vector<Eigen::Vector3d>& dirs, int channels,
                           std::uint64_t seed) {
  const int w = 11, h = 9;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> u(0.1f, 0.6f);
  std::vector<float> albedo(static_cast<std::size_t>(w) * h * 3);
  for (float& a : albedo) a = u(rng);
  std::vector<Image> images;
  for (const auto& d : dirs) {
    Image im(w, h, channels, ColourSpace::kLinear);
    for (int y = 0; y < h; ++y) {
      for (int x = 0; x < w; ++x) {
        const float shade = static_cast<float>(0.3 + 0.6 * d.z() + 0.1 * d.x() * (x - 5) / 5.0);
        for (int c = 0; c < 3 && c < channels; ++c) {
          im.at(x, y, c) = albedo[(static_cast<std::size_t>(y) * w + x) * 3 + c] * shade;
        }
        if (channels == 4) im.at(x, y, 3) = 0.25f + 0.5f * static_cast<float>(x) / w;
      }
    }
    images.push_back(std::move(im));
  }
  return images;
}

// The same images without their last (alpha) channel.
std::vector<Image> drop_alpha(const std::vector<Image>& rgba) {
  std::vector<Image> out;
  for (const Image& a : rgba) {
    Image im(a.width(), a.height(), 3, a.colour_space());
    for (int y = 0; y < a.height(); ++y) {
      for (int x = 0; x < a.width(); ++x) {
        for (int c = 0; c < 3; ++c) im.at(x, y, c) = a.at(x, y, c);
      }
    }
    out.push_back(std::move(im));
  }
  return out;
}

TEST(FitPipeline, SampleChannelsDropAlpha) {
  EXPECT_EQ(sample_channels(1), 1);
  EXPECT_EQ(sample_channels(2), 1);
  EXPECT_EQ(sample_channels(3), 3);
  EXPECT_EQ(sample_channels(4), 3);
}

// Images in memory with an alpha channel are fitted as their RGB, for every basis and colour
// model: the same coefficients, bit for bit, as the RGB images (not a grey fit of the red
// channel).
TEST(FitPipeline, RgbaImagesInMemoryAreFittedAsRgb) {
  const auto dirs = geodesic_dome(2);
  const std::vector<Image> rgba = capture(dirs, 4, test::test_seed());
  const std::vector<Image> rgb = drop_alpha(rgba);
  for (Basis basis : {Basis::kPtm, Basis::kHsh3}) {
    for (ColourModel model : {ColourModel::kRGB, ColourModel::kLRGB}) {
      fit::FitOptions o;
      o.basis = basis;
      o.model = model;
      o.band_rows = 4;
      CoefficientMap from_rgba, from_rgb;
      CoefficientMapSink sink_a(&from_rgba), sink_b(&from_rgb);
      const fit::FitReport ra = fit::fit_images(rgba, dirs, o, sink_a);
      (void)fit::fit_images(rgb, dirs, o, sink_b);
      const std::string what = std::string(to_string(basis)) + " " + std::string(to_string(model));
      EXPECT_EQ(ra.channels, 3) << what;
      EXPECT_EQ(from_rgba.basis, basis) << what;
      ASSERT_EQ(from_rgba.coeffs.size(), from_rgb.coeffs.size()) << what;
      EXPECT_EQ(from_rgba.coeffs, from_rgb.coeffs) << what;
      EXPECT_EQ(from_rgba.colour, from_rgb.colour) << what;
      // A colourful scene: the channels of a texel differ when relit (not a grey fit).
      float c[3];
      from_rgba.evaluate(3, 4, Eigen::Vector3d(0.2, 0.1, 0.97).normalized(), c);
      EXPECT_GT(std::abs(c[0] - c[1]) + std::abs(c[1] - c[2]), kColourfulMinSpread) << what;
    }
  }
}

// An HSH fit through the pipeline delivers an rgb layout of the basis's terms; the .rti sink
// writes the same file as write_rti on the map held in memory.
TEST(FitPipeline, HshFitsStreamToEitherSink) {
  ScratchDir dir;
  const auto dirs = geodesic_dome(2);
  const std::vector<Image> images = capture(dirs, 3, test::test_seed() + 1);
  fit::FitOptions o;
  o.basis = Basis::kHsh2;
  o.model = ColourModel::kLRGB;
  CoefficientMap map;
  CoefficientMapSink sink(&map);
  const fit::FitReport rep = fit::fit_images(images, dirs, o, sink);
  EXPECT_EQ(rep.basis, Basis::kHsh2);
  EXPECT_EQ(rep.model, ColourModel::kLRGB);
  EXPECT_EQ(map.model, ColourModel::kRGB);  // multiplied out
  EXPECT_EQ(map.coeffs.size(), map.texels() * 3 * 4);
  texture::RtiWriter writer(dir / "a.rti");
  (void)fit::fit_images(images, dirs, o, writer);
  texture::write_rti(dir / "b.rti", map);
  EXPECT_EQ(std::filesystem::file_size(dir / "a.rti"), writer.report().file_bytes);
  EXPECT_EQ(read_bytes(dir / "a.rti"), read_bytes(dir / "b.rti"));
}

TEST(FitPipeline, SinksRefuseLayoutsTheyCannotStore) {
  ScratchDir dir;
  texture::PtmStreamWriter ptm(dir / "x.ptm");
  EXPECT_THROW(ptm.begin({8, 8, Basis::kHsh3, ColourModel::kRGB, ColourSpace::kSRGB}), Error);
  texture::RtiWriter rti(dir / "x.rti");
  EXPECT_THROW(rti.begin({8, 8, Basis::kPtm, ColourModel::kRGB, ColourSpace::kSRGB}), Error);
  EXPECT_THROW(rti.begin({8, 8, Basis::kHsh3, ColourModel::kLRGB, ColourSpace::kSRGB}), Error);
  EXPECT_FALSE(std::filesystem::exists(dir / "x.ptm"));
  EXPECT_FALSE(std::filesystem::exists(dir / "x.rti"));
}

TEST(FitPipeline, OptionsSayWhatGoesWithABasis) {
  fit::FitOptions o;
  o.basis = Basis::kHsh3;
  EXPECT_EQ(o.validate(), "");
  o.solver = fit::Solver::kRobust;
  EXPECT_NE(o.validate().find("least-squares"), std::string::npos) << o.validate();
  o.solver = fit::Solver::kLS;
  o.model = ColourModel::kYCC;
  EXPECT_NE(o.validate().find("ycc"), std::string::npos) << o.validate();
}

TEST(FitPlan, ChecksTheOutputAndWhatGoesTogether) {
  LightSet lights;  // plan_fit reads no image unless the model is chosen (auto)
  fit::FitRequest r;
  r.output = "out.rti";
  EXPECT_THROW((void)fit::plan_fit(lights, r), Error);  // ptm to .rti
  r.model = fit::ModelRequest::kHsh3;
  const fit::FitPlan p = fit::plan_fit(lights, r);
  EXPECT_EQ(p.options.basis, Basis::kHsh3);
  EXPECT_EQ(p.format, fit::CoefficientFormat::kRti);
  r.wants_maps = true;
  EXPECT_THROW((void)fit::plan_fit(lights, r), Error);  // maps go with ptm
  r.wants_maps = false;
  r.options.solver = fit::Solver::kRobust;
  EXPECT_THROW((void)fit::plan_fit(lights, r), Error);  // robust goes with ptm
  EXPECT_EQ(fit::parse_model_request("auto"), fit::ModelRequest::kAuto);
  EXPECT_THROW((void)fit::parse_model_request("hsh5"), Error);
}

// A failure writing an optional map leaves no .ptm either: every output of `ptmkit fit`
// commits together.
TEST(FitCli, AFailedMapLeavesNoPtm) {
  ScratchDir dir;
  const auto cap = dir / "cap";
  const test::RunResult synth = test::run_ptmkit(
      {"synth", "--preset", "default", "--size", "24", "--out", cap.string(), "--no-truth"});
  ASSERT_EQ(synth.exit_code, 0) << synth.err;
  const auto ptm = dir / "out.ptm";
  const auto report = dir / "fit.json";
  const test::RunResult r =
      test::run_ptmkit({"fit", (cap / "lights.lp").string(), "-o", ptm.string(), "--report",
                        report.string(), "--normals", (dir / "missing" / "n.png").string()});
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_NE(r.err.find("missing"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(ptm));
  EXPECT_FALSE(std::filesystem::exists(report));
  for (const auto& e : std::filesystem::directory_iterator(dir.path())) {
    EXPECT_NE(e.path().filename().string().rfind(std::string(kTempPrefix), 0), 0u) << e.path();
  }
  // The same command with a folder that exists writes all of them.
  const test::RunResult ok =
      test::run_ptmkit({"fit", (cap / "lights.lp").string(), "-o", ptm.string(), "--report",
                        report.string(), "--normals", (dir / "n.png").string()});
  EXPECT_EQ(ok.exit_code, 0) << ok.err;
  EXPECT_TRUE(std::filesystem::exists(ptm));
  EXPECT_TRUE(std::filesystem::exists(report));
  EXPECT_TRUE(std::filesystem::exists(dir / "n.png"));
}

}  // namespace
}  // namespace ptmkit
