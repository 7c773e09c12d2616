#include "ptmkit/eval/compare.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <set>
#include <sstream>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "ptmkit/core/atomic_file.h"
#include "ptmkit/core/colour.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/holdout.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/core/light_set.h"
#include "ptmkit/eval/heldout.h"
#include "ptmkit/fit/fit.h"

namespace fs = std::filesystem;

namespace ptmkit::eval {

using fit::FitOptions;
using fit::FitOutputs;
using fit::FitReport;
using fit::Solver;

namespace {

struct Capture {
  std::vector<Image> images;
  std::vector<Eigen::Vector3d> dirs;
  std::vector<fs::path> files;
  bool integer = true;  // integer files: predictions clamp to [0, 1]
};

Capture load_capture(const fs::path& lp, int* width, int* height) {
  const LightSet set = read_lp(lp);
  Capture c;
  c.dirs = set.directions();
  c.files = set.images();
  for (const fs::path& f : c.files) {
    const ImageInfo info = probe_image(f);
    if (info.format == PixelFormat::kF32) c.integer = false;
    Image img = read_image(f);
    if (*width == 0) {
      *width = img.width();
      *height = img.height();
    }
    if (img.width() != *width || img.height() != *height) {
      throw Error(f.string() + ": " + std::to_string(img.width()) + "x" +
                  std::to_string(img.height()) + ", expected " + std::to_string(*width) + "x" +
                  std::to_string(*height) + " like the capture's first image");
    }
    c.images.push_back(std::move(img));
  }
  return c;
}

struct Truth {
  std::vector<Image> diffuse;  // empty when only normals are known
  Image normals;
  Image mask;  // optional: normal error only where its first channel > 0.5
};

void check_normals(const Truth& t, const Capture& cap, const fs::path& where) {
  if (t.normals.width() != cap.images[0].width() || t.normals.height() != cap.images[0].height() ||
      t.normals.channels() < 3) {
    throw Error(where.string() + ": the normal map's size or channels differ from the capture's");
  }
  if (!t.mask.empty() &&
      (t.mask.width() != t.normals.width() || t.mask.height() != t.normals.height())) {
    throw Error(where.string() + ": the mask's size differs from the capture's");
  }
}

// The truth beside the capture's light file, if any: a `ptmkit synth` set (truth.json,
// truth/diffuse/, truth/normals.exr or .png), or just a normal map `normals.png` (and
// optionally `mask.png`), as the SynthRTI benchmark ships.
std::optional<Truth> load_truth(const fs::path& lp, const Capture& cap) {
  const fs::path dir = lp.parent_path();
  Truth t;
  if (!fs::exists(dir / "truth.json")) {
    if (!fs::exists(dir / "normals.png")) return std::nullopt;
    t.normals = read_normal_map(dir / "normals.png");
    if (fs::exists(dir / "mask.png")) t.mask = read_image(dir / "mask.png");
    check_normals(t, cap, dir / "normals.png");
    return t;
  }
  for (const fs::path& f : cap.files) {
    const fs::path d = dir / "truth" / "diffuse" / f.filename();
    if (!fs::exists(d)) {
      throw Error(d.string() + ": missing diffuse truth (" + (dir / "truth.json").string() +
                  " says this is a synthetic capture)");
    }
    Image img = read_image(d);
    if (img.width() != cap.images[0].width() || img.height() != cap.images[0].height()) {
      throw Error(d.string() + ": size differs from the capture's images");
    }
    t.diffuse.push_back(std::move(img));
  }
  const fs::path exr = dir / "truth" / "normals.exr";
  const fs::path png = dir / "truth" / "normals.png";
  if (fs::exists(exr)) {
    t.normals = read_image(exr);
  } else if (fs::exists(png)) {
    t.normals = read_normal_map(png);
  } else {
    throw Error(exr.string() + ": missing true normals (nor normals.png beside it)");
  }
  check_normals(t, cap, dir / "truth");
  return t;
}

FitOptions base_options(const CompareOptions& o, Solver s) {
  FitOptions f;
  f.model = o.model;
  f.threads = o.threads;
  f.robust = o.robust;
  f.design = o.design;
  f.solver = s;
  f.residual_stats = false;
  return f;
}

void mark_pareto(CompareReport* r) {
  for (auto& a : r->results) {
    a.pareto = true;
    for (const auto& b : r->results) {
      if (&a == &b) continue;
      const bool no_worse = b.us_per_texel <= a.us_per_texel && r->accuracy(b) >= r->accuracy(a);
      const bool better = b.us_per_texel < a.us_per_texel || r->accuracy(b) > r->accuracy(a);
      if (no_worse && better) {
        a.pareto = false;
        break;
      }
    }
  }
}

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

std::string CompareOptions::validate() const {
  if (solvers.empty()) return "no solvers given";
  std::set<Solver> seen;
  for (Solver s : solvers) {
    if (!seen.insert(s).second)
      return "solver '" + std::string(fit::to_string(s)) + "' given twice";
  }
  if (folds < 2) return "folds must be at least 2";
  if (threads < 0) return "threads must be >= 0 (0 = all cores)";
  if (timing_repeats < 1) return "timing_repeats must be at least 1";
  return robust.validate();
}

CompareReport compare_solvers(const fs::path& capture_lp, const std::optional<fs::path>& test_lp,
                              const CompareOptions& options) {
  if (const auto err = options.validate(); !err.empty()) throw Error("compare: " + err);
  CompareReport report;
  report.capture = capture_lp;
  int w = 0, h = 0;
  const Capture cap = load_capture(capture_lp, &w, &h);
  report.width = w;
  report.height = h;
  report.channels = std::min(cap.images[0].channels(), 3);
  report.lights = static_cast<int>(cap.dirs.size());
  report.condition_number = fit::analyse_design(cap.dirs, options.design).condition_number;
  std::optional<Capture> test;
  if (test_lp) {
    report.test = *test_lp;
    test = load_capture(*test_lp, &w, &h);
    report.test_lights = static_cast<int>(test->dirs.size());
  } else {
    if (options.folds > report.lights) {
      throw Error("compare: " + std::to_string(options.folds) + " folds but " +
                  capture_lp.string() + " has only " + std::to_string(report.lights) + " lights");
    }
    report.folds = options.folds;
    report.test_lights = report.lights;
  }
  const std::optional<Truth> truth = load_truth(capture_lp, cap);
  report.has_truth = truth.has_value() && !truth->diffuse.empty();
  report.has_normals = truth.has_value();
  const std::size_t ns = options.solvers.size();
  report.results.resize(ns);
  std::vector<HeldOutScore> held(ns);
  const double texels = static_cast<double>(w) * h;

  for (std::size_t k = 0; k < ns; ++k) {
    const Solver s = options.solvers[k];
    SolverResult& r = report.results[k];
    r.solver = s;
    CoefficientMap map;
    for (int rep = 0; rep < options.timing_repeats; ++rep) {
      CoefficientMapSink sink(&map);
      const FitReport fr = fit::fit_images(cap.images, cap.dirs, base_options(options, s), sink);
      if (rep == 0 || fr.fit_seconds < r.fit_seconds) {
        r.fit_seconds = fr.fit_seconds;
        r.wall_seconds = fr.total_seconds;
      }
      report.threads = fr.threads;
      const double total = std::max(1.0, static_cast<double>(fr.outliers.samples));
      r.shadow_fraction = static_cast<double>(fr.outliers.shadows) / total;
      r.highlight_fraction = static_cast<double>(fr.outliers.highlights) / total;
    }
    r.us_per_texel = 1e6 * r.fit_seconds / texels;
    r.mtexels_per_second = r.wall_seconds > 0 ? texels / r.wall_seconds / 1e6 : 0.0;
    if (test) {
      for (std::size_t i = 0; i < test->dirs.size(); ++i) {
        held[k].add(map, test->dirs[i], test->images[i], test->integer, options.ssim);
      }
    }
    if (truth) {
      const FitOptions o = base_options(options, s);
      FitOutputs out;
      out.want_labels = report.has_truth;
      out.want_normals = true;
      CoefficientMap tmap;
      CoefficientMapSink sink(&tmap);
      (void)fit::fit_images(cap.images, cap.dirs, o, sink, &out);
      r.normals =
          normal_error(out.normals, truth->normals, truth->mask.empty() ? nullptr : &truth->mask);
      if (report.has_truth) {
        r.truth_psnr_db =
            psnr_against_truth(tmap, cap.dirs, truth->diffuse, truth->normals).psnr_db;
        r.outliers =
            outlier_scores(out.labels, cap.images, truth->diffuse, cap.dirs, truth->normals, true);
      }
    }
  }

  if (!test) {
    // Folds outermost: one training set in memory at a time, shared by every solver.
    const int kf = options.folds;
    const std::vector<Fold> folds = kfold_splits(report.lights, kf);
    for (int f = 0; f < kf; ++f) {
      const Fold& fold = folds[static_cast<std::size_t>(f)];
      std::vector<Image> train;
      std::vector<Eigen::Vector3d> train_dirs;
      for (int i : fold.train) {
        train.push_back(cap.images[static_cast<std::size_t>(i)]);
        train_dirs.push_back(cap.dirs[static_cast<std::size_t>(i)]);
      }
      for (std::size_t k = 0; k < ns; ++k) {
        CoefficientMap map;
        CoefficientMapSink sink(&map);
        try {
          (void)fit::fit_images(train, train_dirs, base_options(options, options.solvers[k]), sink);
        } catch (const Error& e) {
          throw Error(capture_lp.string() + ": fold " + std::to_string(f + 1) + " of " +
                      std::to_string(kf) + " (lights i with i mod " + std::to_string(kf) + " = " +
                      std::to_string(f) + " held out) cannot be fitted: " + e.what());
        }
        for (int i : fold.test) {
          const auto u = static_cast<std::size_t>(i);
          held[k].add(map, cap.dirs[u], cap.images[u], cap.integer, options.ssim);
        }
      }
    }
  }
  for (std::size_t k = 0; k < ns; ++k) {
    SolverResult& r = report.results[k];
    r.heldout_psnr_db = held[k].psnr_db();
    r.heldout_samples = held[k].samples();
    r.heldout_ssim = held[k].mean_ssim();
  }
  mark_pareto(&report);
  return report;
}

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
