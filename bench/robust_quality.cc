// Robust solvers against the synth presets' ground truth: per preset, an oracle (weighted
// least squares on the truly good samples) and every solver's PSNR against the diffuse truth,
// outlier precision/recall and normal error. The measurement behind docs/SOLVERS.md's tables.
//
// Usage: robust_quality SIZE [SOLVERS]   (SOLVERS: comma-separated, default
//   ls,irls-huber,irls-tukey,trim,sign). Tuning overrides for experiments, from the
//   environment: RK_HI (highlight_k), RK_SH (shadow_k), RK_MS (min_scale, grey levels),
//   RK_DF (dark_fraction), RK_IT (max_iterations), RK_MI (min_inliers), RK_KW (keep_within,
//   grey levels), RK_KF (keep_within_fraction); RK_LIGHTS, the presets' light layout (as
//   `ptmkit synth --lights`).
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <string>

#include "ptmkit/core/error.h"
#include "synth_stack.h"

namespace ptmkit::fit {
namespace {

// The robust solvers' defaults, with the tuning overrides from the environment (above).
RobustOptions robust_from_env() {
  RobustOptions ro;
  auto envd = [](const char* k, double d) {
    const char* v = std::getenv(k);
    return v ? std::atof(v) : d;
  };
  ro.highlight_k = envd("RK_HI", ro.highlight_k);
  ro.shadow_k = envd("RK_SH", ro.shadow_k);
  ro.min_scale = envd("RK_MS", ro.min_scale * 255) / 255;
  ro.dark_fraction = envd("RK_DF", ro.dark_fraction);
  ro.max_iterations = static_cast<int>(envd("RK_IT", ro.max_iterations));
  ro.min_inliers = static_cast<int>(envd("RK_MI", ro.min_inliers));
  ro.keep_within = envd("RK_KW", ro.keep_within * 255) / 255;
  ro.keep_within_fraction = envd("RK_KF", ro.keep_within_fraction);
  return ro;
}

void print_table(int size, const std::string& list) {
  for (const char* preset : {"default", "matte", "glossy", "tall", "ambient"}) {
    const char* layout = std::getenv("RK_LIGHTS");
    const auto stack = test::render_preset(preset, size, -1.0, -1.0, layout ? layout : "");
    {
      // Oracle: weighted least squares on the truly good samples (lit, within 20 grey levels).
      const LightDesign design = LightDesign::build(stack.dirs);
      TexelSolver ts(design.design(), Solver::kSign, RobustOptions{});
      CoefficientMap map(size, size, ColourModel::kRGB, ColourSpace::kLinear);
      const std::size_t n = stack.dirs.size();
      std::vector<double> w(n), v(n);
      std::uint64_t below = 0, above = 0;
      for (int y = 0; y < size; ++y)
        for (int x = 0; x < size; ++x) {
          for (std::size_t i = 0; i < n; ++i) {
            const bool lit = eval::is_lit(stack.scene.normals, x, y, stack.dirs[i]);
            double d = 0;
            for (int c = 0; c < 3; ++c)
              d += (stack.observed[i].at(x, y, c) - stack.diffuse[i].at(x, y, c)) / 3;
            w[i] = lit && std::abs(d) * 255 <= 20 ? 1.0 : 0.0;
            below += d * 255 < -20;
            above += d * 255 > 20;
          }
          for (int c = 0; c < 3; ++c) {
            for (std::size_t i = 0; i < n; ++i) v[i] = stack.observed[i].at(x, y, c);
            double cc[6];
            ts.weighted_fit(v.data(), w.data(), cc);
            for (int t = 0; t < 6; ++t)
              map.texel_coeffs(x, y)[c * 6 + t] = static_cast<float>(cc[t]);
          }
        }
      std::printf(
          "%-8s oracle psnr %6.2f   true outliers below %llu above %llu\n", preset,
          eval::psnr_against_truth(map, stack.dirs, stack.diffuse, stack.scene.normals).psnr_db,
          static_cast<unsigned long long>(below), static_cast<unsigned long long>(above));
    }
    double ls_psnr = 0.0;
    std::size_t a = 0;
    while (a <= list.size()) {
      std::size_t b = list.find(',', a);
      if (b == std::string::npos) b = list.size();
      const Solver s = parse_solver(list.substr(a, b - a));
      a = b + 1;
      const RobustOptions ro = robust_from_env();
      const auto r = test::score_solver(stack, s, ro);
      if (s == Solver::kLS) ls_psnr = r.psnr_db;
      std::printf(
          "%-8s %-12s psnr %6.2f (%+5.2f)  P/R all %.3f/%.3f  lit %.3f/%.3f  normals %5.2f deg  "
          "%.2f us/texel\n",
          preset, std::string(to_string(s)).c_str(), r.psnr_db, r.psnr_db - ls_psnr,
          r.outliers_all.precision, r.outliers_all.recall, r.outliers_lit.precision,
          r.outliers_lit.recall, r.normals.mean_deg, 1e6 * r.report.fit_seconds / (size * size));
    }
  }
}

}  // namespace
}  // namespace ptmkit::fit

namespace ptmkit::fit {
namespace {

// The broad-lobe render (default preset, Blinn-Phong ks and exponent replaced): every solver's
// normals of the kept samples against the truth, PSNR and outlier precision/recall on lit
// samples.
void print_lobe(int size, double ks, double exponent) {
  const auto stack = test::render_preset("default", size, ks, exponent);
  std::printf("broad lobe: %d px, ks %.2f, exponent %.1f\n", size, ks, exponent);
  for (const char* name : {"ls", "trim", "lambert", "qtrim", "robust"}) {
    const auto r = test::score_solver(stack, parse_solver(name), robust_from_env());
    std::printf("%-10s normals %5.2f deg  psnr %6.2f  P/R lit %.3f/%.3f\n", name,
                r.normals.mean_deg, r.psnr_db, r.outliers_lit.precision, r.outliers_lit.recall);
  }
}

// test::render_ball (tests/support/synth_stack.h): normals of the kept samples against the
// truth, over the ball and by the tilt of its normals.
void print_ball(int size, double ks, double exponent, double cone_deg, double exposure) {
  const test::BallStack st = test::render_ball(size, ks, exponent, cone_deg, exposure);
  const Image& mask = st.mask;
  const double r_ball = st.radius_px, c = 0.5 * (size - 1);
  // The ball's texels by the tilt of their normal from the view axis.
  struct Ring {
    const char* name;
    double lo_deg, hi_deg;
    Image mask;
  };
  std::vector<Ring> rings = {
      {"0-30", 0, 30, {}}, {"30-50", 30, 50, {}}, {"50-70", 50, 70, {}}, {"70+", 70, 90, {}}};
  for (Ring& ring : rings) {
    ring.mask = Image(size, size, 1);
    for (int y = 0; y < size; ++y) {
      for (int x = 0; x < size; ++x) {
        const double rr = std::hypot(x - c, y - c) / r_ball;
        const double tilt = rr < 1.0 ? std::asin(rr) * 180.0 / 3.14159265358979 : 90.0;
        ring.mask.at(x, y, 0) =
            mask.at(x, y, 0) > 0.5f && tilt >= ring.lo_deg && tilt < ring.hi_deg ? 1.0f : 0.0f;
      }
    }
  }
  std::printf("ball: %d px, ks %.2f, exponent %.1f, 96 lights within %.0f deg, exposure %.2f\n",
              size, ks, exponent, cone_deg, exposure);
  for (const char* name : {"ls", "trim", "lambert", "qtrim", "robust"}) {
    fit::RobustOptions ro = robust_from_env();
    ro.min_scale *= 255.0 / 65535.0;  // 16-bit samples, as a fit from the files takes them
    const auto r = test::score_solver(st, parse_solver(name), ro, &mask);
    const eval::NormalError& e = r.normals;
    std::printf("%-10s normals mean %5.2f median %5.2f deg; by tilt", name, e.mean_deg,
                e.median_deg);
    for (const Ring& ring : rings) {
      const eval::NormalError er = eval::normal_error(r.normal_map, st.scene.normals, &ring.mask);
      std::printf(" %s %5.2f", ring.name, er.mean_deg);
    }
    std::printf("\n");
  }
}

}  // namespace
}  // namespace ptmkit::fit

int main(int argc, char** argv) {
  if (argc >= 3 && std::string(argv[1]) == "lobe") {
    try {
      ptmkit::fit::print_lobe(std::atoi(argv[2]), argc > 3 ? std::atof(argv[3]) : 0.25,
                              argc > 4 ? std::atof(argv[4]) : 8.0);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "robust_quality: %s\n", e.what());
      return 1;
    }
    return 0;
  }
  if (argc >= 3 && std::string(argv[1]) == "ball") {
    try {
      ptmkit::fit::print_ball(std::atoi(argv[2]), argc > 3 ? std::atof(argv[3]) : 0.3,
                              argc > 4 ? std::atof(argv[4]) : 10.0,
                              argc > 5 ? std::atof(argv[5]) : 45.0,
                              argc > 6 ? std::atof(argv[6]) : 1.0);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "robust_quality: %s\n", e.what());
      return 1;
    }
    return 0;
  }
  if (argc < 2 || argc > 3 || std::atoi(argv[1]) < 8) {
    std::fprintf(stderr,
                 "usage: robust_quality SIZE(>= 8 px) [SOLVERS]\n"
                 "       robust_quality lobe SIZE [KS EXPONENT]   (default 0.25 8)\n"
                 "       robust_quality ball SIZE [KS EXPONENT CONE_DEG EXPOSURE]   (default 0.3 "
                 "10 45 1)\n");
    return 2;
  }
  try {
    ptmkit::fit::print_table(std::atoi(argv[1]),
                             argc > 2 ? argv[2] : "ls,irls-huber,irls-tukey,trim,sign");
  } catch (const std::exception& e) {
    std::fprintf(stderr, "robust_quality: %s\n", e.what());
    return 1;
  }
  return 0;
}
