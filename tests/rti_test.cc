// HSH .rti files: the basis against its general definition, write/read round trip, malformed files,
// relighting (library and CLI).
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <fstream>
#include <numbers>
#include <random>
#include <string>

#include "ptmkit/core/error.h"
#include "ptmkit/core/hsh.h"
#include "ptmkit/fit/basis.h"
#include "ptmkit/texture/relight.h"
#include "ptmkit/texture/rti.h"
#include "test_util.h"
#include "tolerances.h"

namespace ptmkit {
namespace {

using test::kFloatRoundoff;
using test::kFloatSumRoundoff;
using test::kHalf8BitStep;
using test::ScratchDir;

// The closed forms of the basis against the general definition: both sides are a few dozen
// double operations on values of order 1, so agreement to this is rounding; a wrong constant,
// power or sign is off by far more.
constexpr double kBasisRoundingTol = 1e-12;

CoefficientMap random_map(int w, int h, int terms, std::uint64_t seed) {
  const Basis basis = terms == 4 ? Basis::kHsh2 : terms == 9 ? Basis::kHsh3 : Basis::kHsh4;
  CoefficientMap m({w, h, basis, ColourModel::kRGB, ColourSpace::kSRGB});
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> u(-0.5f, 0.5f);
  for (float& c : m.coeffs) c = u(rng);
  return m;
}

void write_bytes(const std::filesystem::path& p, const std::string& s) {
  std::ofstream f(p, std::ios::binary);
  f << s;
}

std::string read_bytes(const std::filesystem::path& p) {
  std::ifstream f(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>()};
}

// The closed forms of core/hsh.h against the general definition of the hemispherical
// harmonics: H_l^m(theta, phi) = K_l^m P_l^|m|(2 cos theta - 1) times 1 (m = 0),
// sqrt(2) cos(m phi) (m > 0) or sqrt(2) sin(|m| phi) (m < 0), with
// K_l^m = sqrt((2l + 1) / (2 pi) (l - |m|)! / (l + |m|)!) and P the associated Legendre
// functions (std::assoc_legendre, without the Condon-Shortley phase). The .rti order puts
// cos(m phi) at index l^2 + l - m and sin(m phi) at l^2 + l + m, and the viewers' convention
// flips the sign of the m = 2 terms.
double hsh_reference(int index, double theta, double phi) {
  int l = 0;
  while ((l + 1) * (l + 1) <= index) ++l;
  const int k = index - l * l - l;  // -l .. l: negative for cos(|k| phi), positive for sin
  const int m = std::abs(k);
  double fact = 1.0;  // (l - m)! / (l + m)!
  for (int i = l - m + 1; i <= l + m; ++i) fact /= i;
  const double pi = std::numbers::pi;
  const double kn = std::sqrt((2 * l + 1) / (2 * pi) * fact);
  const double p = std::assoc_legendre(static_cast<unsigned>(l), static_cast<unsigned>(m),
                                       2 * std::cos(theta) - 1);
  if (m == 0) return kn * p;
  const double sign = m == 2 ? -1.0 : 1.0;
  const double angular = k < 0 ? std::cos(m * phi) : std::sin(m * phi);
  return sign * std::sqrt(2.0) * kn * p * angular;
}

TEST(RtiBasis, ClosedFormsMatchTheGeneralDefinition) {
  // Below the viewers' clamp of theta (pi/2 - 0.04), where the closed forms are unclamped.
  constexpr double kMaxThetaRad = std::numbers::pi / 2 - 0.05;
  std::mt19937_64 rng(test::test_seed());
  std::uniform_real_distribution<double> ut(0.0, kMaxThetaRad);
  std::uniform_real_distribution<double> up(-std::numbers::pi, std::numbers::pi);
  for (int i = 0; i < 200; ++i) {
    const double theta = ut(rng), phi = up(rng);
    const Eigen::Vector3d d(std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi),
                            std::cos(theta));
    double h[16];
    hsh_basis(16, d, h);
    for (int k = 0; k < 16; ++k)
      EXPECT_NEAR(h[k], hsh_reference(k, theta, phi), kBasisRoundingTol) << "term " << k;
    // Fewer terms are a prefix of the 16.
    double h4[4], h9[9];
    hsh_basis(4, d, h4);
    hsh_basis(9, d, h9);
    for (int k = 0; k < 4; ++k) EXPECT_EQ(h4[k], h[k]);
    for (int k = 0; k < 9; ++k) EXPECT_EQ(h9[k], h[k]);
  }
  // At and below the horizon theta is clamped: the values of theta = pi/2 - 0.04.
  const double clamp = std::numbers::pi / 2 - 0.04;
  for (double phi : {0.3, 2.0, -2.5}) {
    double at[16], below[16], edge[16];
    hsh_basis(16, Eigen::Vector3d(std::cos(phi), std::sin(phi), 0.0), at);
    hsh_basis(16, Eigen::Vector3d(std::cos(phi), std::sin(phi), -0.2), below);
    hsh_basis(16,
              Eigen::Vector3d(std::sin(clamp) * std::cos(phi), std::sin(clamp) * std::sin(phi),
                              std::cos(clamp)),
              edge);
    for (int k = 0; k < 16; ++k) {
      EXPECT_NEAR(at[k], edge[k], kBasisRoundingTol) << "term " << k;
      EXPECT_NEAR(below[k], edge[k], kBasisRoundingTol) << "term " << k;
    }
  }
  // The fit evaluates the .rti basis (the viewers' order): a basis name maps to its terms.
  for (const fit::Basis b : {fit::Basis::kHsh2, fit::Basis::kHsh3, fit::Basis::kHsh4}) {
    double a[16], f[16];
    const Eigen::Vector3d d(0.3, -0.4, 0.8);
    hsh_basis(fit::basis_terms(b), d, a);
    fit::evaluate_basis(b, d, f);
    for (int k = 0; k < fit::basis_terms(b); ++k) EXPECT_EQ(a[k], f[k]) << "term " << k;
  }
  // Overhead light: only the zonal terms (h0, h2, h6, h12) are non-zero, at their c = 1 values.
  double h[16];
  texture::hsh_basis(16, Eigen::Vector3d(0, 0, 1), h);
  const double pi = 3.14159265358979323846;
  EXPECT_NEAR(h[0], 1 / std::sqrt(2 * pi), kBasisRoundingTol);
  EXPECT_NEAR(h[1], 0.0, kBasisRoundingTol);
  EXPECT_NEAR(h[2], std::sqrt(3 / (2 * pi)), kBasisRoundingTol);
  EXPECT_NEAR(h[6], std::sqrt(5 / (2 * pi)), kBasisRoundingTol);
  EXPECT_NEAR(h[12], std::sqrt(7 / (2 * pi)), kBasisRoundingTol);
}

TEST(RtiFile, WriteReadRoundTrip) {
  ScratchDir dir;
  for (int terms : {4, 9, 16}) {
    const CoefficientMap m = random_map(7, 5, terms, test::test_seed() + terms);
    std::string name = "m";
    name.append(std::to_string(terms)).append(".rti");
    const auto path = dir / name;
    const texture::RtiWriteReport rep = texture::write_rti(path, m);
    EXPECT_EQ(rep.file_bytes, std::filesystem::file_size(path));
    const CoefficientMap r = texture::read_rti(path);
    ASSERT_EQ(r.width, 7);
    ASSERT_EQ(r.height, 5);
    ASSERT_EQ(r.terms(), terms);
    ASSERT_EQ(r.coeffs.size(), m.coeffs.size());
    // Half a quantisation step of a range of at most 1.0.
    double max_err = 0.0;
    for (std::size_t i = 0; i < m.coeffs.size(); ++i) {
      max_err = std::max(max_err, static_cast<double>(std::abs(r.coeffs[i] - m.coeffs[i])));
    }
    EXPECT_LE(max_err, kHalf8BitStep + kFloatRoundoff);
    EXPECT_NEAR(max_err, rep.max_coeff_error, kFloatRoundoff);
    // Writing what was read gives the same bytes (the quantisation is reproduced exactly).
    const auto again = dir / "again.rti";
    texture::write_rti(again, r);
    EXPECT_EQ(read_bytes(again).size(), read_bytes(path).size());
    // Header as the viewers expect it: CRLF line ends, as CHI's HSH fitter writes.
    const std::string bytes = read_bytes(path);
    std::string head = "#HSH1.2\r\n3\r\n7 5 3\r\n";
    head.append(std::to_string(terms)).append(" 2 1\r\n");
    EXPECT_EQ(bytes.substr(0, head.size()), head);
    EXPECT_TRUE(texture::looks_like_rti(path));
  }
}

TEST(RtiFile, MalformedFilesNameTheFile) {
  ScratchDir dir;
  const CoefficientMap m = random_map(4, 3, 9, test::test_seed());
  const auto good = dir / "good.rti";
  texture::write_rti(good, m);
  const std::string bytes = read_bytes(good);
  struct Case {
    const char* name;
    std::string content;
    const char* expect;
  };
  const std::string head = "#HSH1.2\r\n3\r\n4 3 3\r\n9 2 1\r\n";
  const std::vector<Case> cases = {
      {"truncated.rti", bytes.substr(0, bytes.size() - 10), "too short"},
      {"type.rti", "#c\n2\n4 3 3\n9 2 1\n" + bytes.substr(head.size()),
       "RTI type 2 is not supported (supported: "},
      {"terms.rti", "#c\n3\n4 3 3\n7 2 1\n" + bytes.substr(head.size()), "7 basis terms"},
      {"components.rti", "#c\n3\n4 3 1\n9 2 1\n" + bytes.substr(head.size()), "components"},
      {"size.rti", "#c\n3\n-4 3 3\n9 2 1\n", "bad size"},
      {"text.rti", "#c\nthree\n", "RTI type"},
      {"empty.rti", "", "not an .rti"},
  };
  for (const Case& c : cases) {
    const auto p = dir / c.name;
    write_bytes(p, c.content);
    try {
      (void)texture::read_rti(p);
      ADD_FAILURE() << c.name << " was accepted";
    } catch (const Error& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find(c.name), std::string::npos) << msg;
      EXPECT_NE(msg.find(c.expect), std::string::npos) << msg;
    }
  }
  EXPECT_THROW((void)texture::read_rti(dir / "missing.rti"), Error);
}

TEST(RtiRelight, MatchesTheBasisSumAndTheCli) {
  ScratchDir dir;
  CoefficientMap m = random_map(6, 4, 9, test::test_seed() + 7);
  for (float& c : m.coeffs) c = 0.3f + 0.2f * c;
  const auto path = dir / "t.rti";
  texture::write_rti(path, m);
  const CoefficientMap r = texture::read_rti(path);
  const Eigen::Vector3d l = Eigen::Vector3d(0.3, -0.2, 0.8).normalized();
  texture::RelightOptions no_clamp;
  no_clamp.clamp = false;
  const Image img = texture::relight(r, l, no_clamp);
  double b[9];
  texture::hsh_basis(9, l, b);
  for (int y = 0; y < r.height; ++y) {
    for (int x = 0; x < r.width; ++x) {
      for (int k = 0; k < 3; ++k) {
        double v = 0.0;
        for (int j = 0; j < 9; ++j) v += r.texel_coeffs(x, y)[k * 9 + j] * b[j];
        EXPECT_NEAR(img.at(x, y, k), v, kFloatSumRoundoff);
      }
    }
  }
  // Light from behind: black.
  const Image behind = texture::relight(r, Eigen::Vector3d(0, 0, -1));
  for (std::size_t i = 0; i < behind.size(); ++i) EXPECT_EQ(behind.data()[i], 0.0f);
  // The CLI reads .rti too.
  const auto out = dir / "relit.png";
  const test::RunResult run =
      test::run_ptmkit({"relight", path.string(), "--light", "0.3,-0.2,0.8", "-o", out.string()});
  EXPECT_EQ(run.exit_code, 0) << run.err;
  EXPECT_TRUE(std::filesystem::exists(out));
  EXPECT_NE(run.out.find("HSH 9 terms"), std::string::npos) << run.out;
  // `ptmkit info` describes it: order, size, and each term's range as stored.
  const test::RunResult info = test::run_ptmkit({"info", path.string(), "--json"});
  ASSERT_EQ(info.exit_code, 0) << info.err;
  const auto j = nlohmann::json::parse(info.out);
  EXPECT_EQ(j["hsh_order"], 3);
  EXPECT_EQ(j["terms"], 9);
  EXPECT_EQ(j["width"], 6);
  EXPECT_EQ(j["height"], 4);
  for (int k = 0; k < 9; ++k) {
    float lo = 1e9f, hi = -1e9f;
    for (std::size_t i = static_cast<std::size_t>(k); i < r.coeffs.size(); i += 9) {
      lo = std::min(lo, r.coeffs[i]);
      hi = std::max(hi, r.coeffs[i]);
    }
    EXPECT_NEAR(j["coeff_min"][static_cast<std::size_t>(k)].get<double>(), lo, kFloatRoundoff);
    EXPECT_NEAR(j["coeff_max"][static_cast<std::size_t>(k)].get<double>(), hi, kFloatRoundoff);
  }
  const test::RunResult text = test::run_ptmkit({"info", path.string()});
  EXPECT_EQ(text.exit_code, 0) << text.err;
  EXPECT_NE(text.out.find("RTI HSH order 3 (9 terms per channel), 6 x 4 texels"), std::string::npos)
      << text.out;
}

}  // namespace
}  // namespace ptmkit
