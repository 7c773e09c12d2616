// HSH .rti files: basis agreement between stages, write/read round trip, malformed files,
// relighting (library and CLI).
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <fstream>
#include <random>
#include <string>

#include "ptmkit/core/error.h"
#include "ptmkit/fit/basis.h"
#include "ptmkit/texture/relight.h"
#include "ptmkit/texture/rti.h"
#include "test_util.h"

namespace ptmkit {
namespace {

using test::ScratchDir;

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

TEST(RtiBasis, FitAndTextureStagesAgree) {
  std::mt19937_64 rng(test::test_seed());
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int i = 0; i < 200; ++i) {
    Eigen::Vector3d d(u(rng), u(rng), std::abs(u(rng)) + 0.01);
    d.normalize();
    for (int order = 2; order <= 4; ++order) {
      const int t = texture::hsh_terms(order);
      double a[16], b[16];
      texture::hsh_basis(t, d, a);
      const fit::Basis basis = order == 2   ? fit::Basis::kHsh2
                               : order == 3 ? fit::Basis::kHsh3
                                            : fit::Basis::kHsh4;
      fit::evaluate_basis(basis, d, b);
      for (int k = 0; k < t; ++k) EXPECT_NEAR(a[k], b[k], 1e-12) << "term " << k;
    }
  }
  // Overhead light: only the zonal terms (h0, h2, h6, h12) are non-zero, at their c = 1 values.
  double h[16];
  texture::hsh_basis(16, Eigen::Vector3d(0, 0, 1), h);
  const double pi = 3.14159265358979323846;
  EXPECT_NEAR(h[0], 1 / std::sqrt(2 * pi), 1e-12);
  EXPECT_NEAR(h[1], 0.0, 1e-12);
  EXPECT_NEAR(h[2], std::sqrt(3 / (2 * pi)), 1e-12);
  EXPECT_NEAR(h[6], std::sqrt(5 / (2 * pi)), 1e-12);
  EXPECT_NEAR(h[12], std::sqrt(7 / (2 * pi)), 1e-12);
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
    EXPECT_LE(max_err, 0.5 / 255.0 + 1e-6);
    EXPECT_NEAR(max_err, rep.max_coeff_error, 1e-6);
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
        EXPECT_NEAR(img.at(x, y, k), v, 1e-5);
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
    EXPECT_NEAR(j["coeff_min"][static_cast<std::size_t>(k)].get<double>(), lo, 1e-6);
    EXPECT_NEAR(j["coeff_max"][static_cast<std::size_t>(k)].get<double>(), hi, 1e-6);
  }
  const test::RunResult text = test::run_ptmkit({"info", path.string()});
  EXPECT_EQ(text.exit_code, 0) << text.err;
  EXPECT_NE(text.out.find("RTI HSH order 3 (9 terms per channel), 6 x 4 texels"), std::string::npos)
      << text.out;
}

}  // namespace
}  // namespace ptmkit
