// The comparison's outputs: JSON, the Markdown table, CSV, the speed/accuracy plot and the
// folder holding them.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <sstream>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "ptmkit/core/atomic_file.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/eval/compare.h"

namespace fs = std::filesystem;

namespace ptmkit::eval {

using fit::Solver;

namespace {

std::string fmt(const char* f, double v) {
  if (!std::isfinite(v)) return "inf";
  char buf[64];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}

const SolverResult* find_ls(const CompareReport& r) {
  for (const auto& s : r.results)
    if (s.solver == Solver::kLS) return &s;
  return nullptr;
}

}  // namespace

std::string CompareReport::to_json() const {
  nlohmann::json j;
  j["capture"] = capture.string();
  j["test"] = test.string();
  j["width"] = width;
  j["height"] = height;
  j["channels"] = channels;
  j["lights"] = lights;
  j["test_lights"] = test_lights;
  j["folds"] = folds;
  j["threads"] = threads;
  j["has_truth"] = has_truth;
  j["has_normals"] = has_normals;
  j["accuracy"] = accuracy_name();
  auto num = [](double v) -> nlohmann::json {
    if (std::isfinite(v)) return v;
    return "inf";
  };
  j["condition_number"] = num(condition_number);
  nlohmann::json arr = nlohmann::json::array();
  for (const auto& r : results) {
    nlohmann::json e;
    e["solver"] = std::string(fit::to_string(r.solver));
    e["fit_seconds"] = r.fit_seconds;
    e["wall_seconds"] = r.wall_seconds;
    e["us_per_texel"] = r.us_per_texel;
    e["mtexels_per_second"] = r.mtexels_per_second;
    e["heldout_psnr_db"] = num(r.heldout_psnr_db);
    e["heldout_ssim"] = r.heldout_ssim;
    e["heldout_samples"] = r.heldout_samples;
    e["shadow_fraction"] = r.shadow_fraction;
    e["highlight_fraction"] = r.highlight_fraction;
    if (has_normals) {
      e["normal_error_deg"] = {{"mean", r.normals.mean_deg}, {"median", r.normals.median_deg}};
    }
    if (has_truth) {
      e["truth_psnr_db"] = num(r.truth_psnr_db);
      e["outliers_lit"] = {{"precision", r.outliers.precision},
                           {"recall", r.outliers.recall},
                           {"true_outliers", r.outliers.true_outliers},
                           {"labelled", r.outliers.labelled},
                           {"samples", r.outliers.samples}};
    }
    e["pareto"] = r.pareto;
    arr.push_back(e);
  }
  j["results"] = arr;
  return j.dump(2) + "\n";
}

std::string CompareReport::to_markdown() const {
  std::ostringstream s;
  s << "# Solver comparison\n\n";
  s << "Capture `" << capture.string() << "`: " << width << "x" << height << ", " << lights
    << " lights, cond(A) " << fmt("%.3g", condition_number) << "; held out: ";
  if (folds > 0) {
    s << folds << " folds over the capture's lights (light i in fold i mod " << folds << ")";
  } else {
    s << test_lights << " lights of `" << test.string() << "`";
  }
  s << "; " << threads << " threads.\n\n";
  const SolverResult* ls = find_ls(*this);
  s << "| solver | us/texel | Mtexel/s | wall s | held-out PSNR dB | SSIM |";
  if (has_truth) s << " truth PSNR dB |";
  if (has_normals) s << " normals deg (mean/median) |";
  if (has_truth) s << " outlier P/R (lit) |";
  s << " shadow % | highlight % | Pareto |\n|---|---|---|---|---|---|";
  if (has_truth) s << "---|---|";
  if (has_normals) s << "---|";
  s << "---|---|---|\n";
  for (const auto& r : results) {
    const bool shared = fit::is_shared_solver(r.solver);
    s << "| " << (r.pareto ? "**" : "") << fit::to_string(r.solver) << (r.pareto ? "**" : "")
      << " | " << fmt("%.2f", r.us_per_texel) << " | " << fmt("%.2f", r.mtexels_per_second) << " | "
      << fmt("%.3f", r.wall_seconds) << " | " << fmt("%.2f", r.heldout_psnr_db);
    if (ls != nullptr && &r != ls)
      s << " (" << fmt("%+.2f", r.heldout_psnr_db - ls->heldout_psnr_db) << ")";
    s << " | " << fmt("%.4f", r.heldout_ssim) << " |";
    if (has_truth) {
      s << " " << fmt("%.2f", r.truth_psnr_db);
      if (ls != nullptr && &r != ls)
        s << " (" << fmt("%+.2f", r.truth_psnr_db - ls->truth_psnr_db) << ")";
      s << " |";
    }
    if (has_normals) {
      s << " " << fmt("%.2f", r.normals.mean_deg) << " / " << fmt("%.2f", r.normals.median_deg)
        << " |";
    }
    if (has_truth) {
      s << " ";
      if (shared) {
        s << "- |";
      } else {
        s << fmt("%.2f", r.outliers.precision) << " / " << fmt("%.2f", r.outliers.recall) << " |";
      }
    }
    s << " " << fmt("%.2f", 100 * r.shadow_fraction) << " | "
      << fmt("%.2f", 100 * r.highlight_fraction) << " | " << (r.pareto ? "yes" : "") << " |\n";
  }
  s << "\nus/texel: fitting time per texel (images in memory); Mtexel/s: texels over the whole "
       "fit call. Held-out PSNR (peak 1.0) and SSIM (luma): predictions at lights the fit did not "
       "see, clamped to the file's range.";
  if (has_truth) {
    s << " Truth PSNR: fit at the capture's lights against the diffuse-only truth over lit "
         "samples; outliers: samples more than 20 grey levels (luma) from the diffuse truth.";
  }
  if (has_normals) {
    s << " Normals: Lambertian photometric stereo on the inlier samples (all samples for the "
         "least-squares solvers) against the true normal map"
      << (has_truth ? "" : " beside the light file (normals.png, within mask.png if present)")
      << ".";
  }
  s << " Pareto: no other solver is both faster and more accurate (" << accuracy_name() << ").\n";
  return s.str();
}

std::string CompareReport::to_csv() const {
  std::ostringstream s;
  s << "solver,us_per_texel,mtexels_per_second,wall_seconds,heldout_psnr_db,heldout_ssim,"
       "truth_psnr_db,normal_mean_deg,normal_median_deg,outlier_precision,outlier_recall,"
       "shadow_fraction,highlight_fraction,pareto\n";
  for (const auto& r : results) {
    s << fit::to_string(r.solver) << "," << fmt("%.4f", r.us_per_texel) << ","
      << fmt("%.4f", r.mtexels_per_second) << "," << fmt("%.5f", r.wall_seconds) << ","
      << fmt("%.4f", r.heldout_psnr_db) << "," << fmt("%.5f", r.heldout_ssim) << ",";
    s << (has_truth ? fmt("%.4f", r.truth_psnr_db) : "") << ",";
    if (has_normals) {
      s << fmt("%.4f", r.normals.mean_deg) << "," << fmt("%.4f", r.normals.median_deg) << ",";
    } else {
      s << ",,";
    }
    if (has_truth) {
      s << fmt("%.4f", r.outliers.precision) << "," << fmt("%.4f", r.outliers.recall) << ",";
    } else {
      s << ",,";
    }
    s << fmt("%.6f", r.shadow_fraction) << "," << fmt("%.6f", r.highlight_fraction) << ","
      << (r.pareto ? 1 : 0) << "\n";
  }
  return s.str();
}

Image plot_tradeoff(const CompareReport& report) {
  constexpr int kW = 800, kH = 520;
  constexpr int kLeft = 80, kRight = 30, kTop = 40, kBottom = 60;
  cv::Mat m(kH, kW, CV_8UC3, cv::Scalar(255, 255, 255));
  const cv::Scalar black(0, 0, 0), grey(150, 150, 150), light(225, 225, 225), red(200, 30, 30),
      blue(40, 70, 180);
  const auto& rs = report.results;
  double xmin = std::numeric_limits<double>::infinity(), xmax = -xmin, ymin = xmin, ymax = -xmin;
  for (const auto& r : rs) {
    const double x = std::log10(std::max(r.us_per_texel, 1e-3));
    const double y = report.accuracy(r);
    if (!std::isfinite(y)) continue;
    xmin = std::min(xmin, x);
    xmax = std::max(xmax, x);
    ymin = std::min(ymin, y);
    ymax = std::max(ymax, y);
  }
  if (!std::isfinite(xmin)) xmin = 0, xmax = 1, ymin = 0, ymax = 1;
  xmin = std::floor(xmin);
  xmax = std::max(std::ceil(xmax), xmin + 1);
  const double ypad = std::max(0.5, 0.1 * (ymax - ymin));
  ymin = std::floor(ymin - ypad);
  ymax = std::ceil(ymax + ypad);
  const auto px = [&](double lx) {
    return kLeft +
           static_cast<int>(std::lround((lx - xmin) / (xmax - xmin) * (kW - kLeft - kRight)));
  };
  const auto py = [&](double y) {
    return kTop + static_cast<int>(std::lround((ymax - y) / (ymax - ymin) * (kH - kTop - kBottom)));
  };
  const int font = cv::FONT_HERSHEY_SIMPLEX;
  // Grid and ticks: decades with 2 and 5 in x, whole dB (or 2, 5 dB) in y.
  for (int d = static_cast<int>(xmin); d <= static_cast<int>(xmax); ++d) {
    for (int f : {1, 2, 5}) {
      const double lx = d + std::log10(f);
      if (lx > xmax + 1e-9) break;
      cv::line(m, {px(lx), kTop}, {px(lx), kH - kBottom}, f == 1 ? grey : light, 1);
      char buf[32];
      std::snprintf(buf, sizeof buf, "%g", std::pow(10.0, lx));
      cv::putText(m, buf, {px(lx) - 12, kH - kBottom + 20}, font, 0.45, black, 1, cv::LINE_AA);
    }
  }
  const double span = ymax - ymin;
  const double step = span <= 12 ? 1.0 : span <= 30 ? 2.0 : 5.0;
  for (double y = std::ceil(ymin / step) * step; y <= ymax + 1e-9; y += step) {
    cv::line(m, {kLeft, py(y)}, {kW - kRight, py(y)}, light, 1);
    char buf[32];
    std::snprintf(buf, sizeof buf, "%g", y);
    cv::putText(m, buf, {kLeft - 40, py(y) + 5}, font, 0.45, black, 1, cv::LINE_AA);
  }
  cv::rectangle(m, {kLeft, kTop}, {kW - kRight, kH - kBottom}, black, 1);
  cv::putText(m, "fit time (us/texel, log scale)", {kW / 2 - 120, kH - 15}, font, 0.55, black, 1,
              cv::LINE_AA);
  cv::putText(m, report.accuracy_name() + " against time; red: Pareto front", {kLeft, kTop - 14},
              font, 0.55, black, 1, cv::LINE_AA);
  // Pareto front, joined in order of time.
  std::vector<const SolverResult*> front;
  for (const auto& r : rs)
    if (r.pareto && std::isfinite(report.accuracy(r))) front.push_back(&r);
  std::sort(front.begin(), front.end(), [](const SolverResult* a, const SolverResult* b) {
    return a->us_per_texel < b->us_per_texel;
  });
  const auto pt = [&](const SolverResult& r) {
    return cv::Point(px(std::log10(std::max(r.us_per_texel, 1e-3))), py(report.accuracy(r)));
  };
  for (std::size_t i = 1; i < front.size(); ++i)
    cv::line(m, pt(*front[i - 1]), pt(*front[i]), red, 2, cv::LINE_AA);
  for (const auto& r : rs) {
    if (!std::isfinite(report.accuracy(r))) continue;
    const cv::Point p = pt(r);
    if (r.pareto) {
      cv::circle(m, p, 6, red, cv::FILLED, cv::LINE_AA);
    } else {
      cv::circle(m, p, 6, blue, 2, cv::LINE_AA);
    }
    cv::putText(m, std::string(fit::to_string(r.solver)), {p.x + 9, p.y - 7}, font, 0.45,
                r.pareto ? red : blue, 1, cv::LINE_AA);
  }
  Image img(kW, kH, 3, ColourSpace::kSRGB);
  for (int y = 0; y < kH; ++y) {
    const auto* row = m.ptr<cv::Vec3b>(y);
    for (int x = 0; x < kW; ++x)
      for (int c = 0; c < 3; ++c) img.at(x, y, c) = static_cast<float>(row[x][c]) / 255.0f;
  }
  return img;
}

void write_compare(const CompareReport& report, const fs::path& out_dir) {
  const std::string md = report.to_markdown();
  const std::string csv = report.to_csv();
  const std::string json = report.to_json();
  const Image plot = plot_tradeoff(report);
  ensure_directory(out_dir);
  write_file_atomic(out_dir / "table.md", md);
  write_file_atomic(out_dir / "results.csv", csv);
  write_file_atomic(out_dir / "results.json", json);
  write_image(out_dir / "plot.png", plot.view(), ImageWriteOptions{PixelFormat::kU8});
}

}  // namespace ptmkit::eval
