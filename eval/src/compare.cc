#include "ptmkit/eval/compare.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>
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
#include "ptmkit/core/stack_reader.h"
#include "ptmkit/eval/heldout.h"
#include "ptmkit/eval/truth.h"
#include "ptmkit/fit/fit.h"

namespace fs = std::filesystem;

namespace ptmkit::eval {

using fit::FitOptions;
using fit::FitOutputs;
using fit::FitReport;
using fit::Solver;

namespace {

// A stack of images read top to bottom and held as a window of rows [lo, hi): the capture,
// the test set or the truth are never in memory whole.
class RowWindow {
 public:
  explicit RowWindow(const std::vector<fs::path>& files) : reader_(files) {}
  [[nodiscard]] const StackReader& reader() const { return reader_; }
  [[nodiscard]] const std::vector<Image>& images() const { return images_; }
  // Moves the window to rows [lo, hi); both only grow, and lo is at most the last hi.
  void move_to(int lo, int hi) {
    const int w = reader_.width();
    const int ch = reader_.channels();
    const std::size_t row_floats = static_cast<std::size_t>(w) * static_cast<std::size_t>(ch);
    std::vector<Image> next;
    next.reserve(static_cast<std::size_t>(reader_.count()));
    for (int i = 0; i < reader_.count(); ++i) {
      next.emplace_back(w, hi - lo, ch, reader_.info().colour_space);
      for (int y = std::max(lo, lo_); y < std::min(hi, hi_); ++y) {
        std::copy_n(images_[static_cast<std::size_t>(i)].row(y - lo_), row_floats,
                    next.back().row(y - lo));
      }
    }
    while (read_ < hi) {
      if (!reader_.read_band(hi - read_, &band_)) break;
      for (int i = 0; i < band_.images; ++i) {
        for (int r = 0; r < band_.rows; ++r) {
          std::copy_n(band_.image(i) + static_cast<std::size_t>(r) * row_floats, row_floats,
                      next[static_cast<std::size_t>(i)].row(band_.y0 + r - lo));
        }
      }
      read_ = band_.y0 + band_.rows;
    }
    images_ = std::move(next);
    lo_ = lo;
    hi_ = hi;
  }

 private:
  StackReader reader_;
  StackBand band_;
  std::vector<Image> images_;
  int lo_ = 0, hi_ = 0, read_ = 0;
};

struct Capture {
  std::vector<Eigen::Vector3d> dirs;
  std::vector<fs::path> files;
  bool integer = true;  // integer files: predictions clamp to [0, 1]
  std::unique_ptr<RowWindow> rows;
};

Capture open_capture(const fs::path& lp) {
  const LightSet set = read_lp(lp);
  Capture c;
  c.dirs = set.directions();
  c.files = set.images();
  for (const fs::path& f : c.files) {
    if (probe_image(f).format == PixelFormat::kF32) c.integer = false;
  }
  c.rows = std::make_unique<RowWindow>(c.files);
  return c;
}

void require_size(const StackReader& r, int w, int h, const std::string& what) {
  if (r.width() != w || r.height() != h) {
    throw Error(r.files().front().string() + ": " + std::to_string(r.width()) + "x" +
                std::to_string(r.height()) + ", expected " + std::to_string(w) + "x" +
                std::to_string(h) + " like " + what);
  }
}

struct Truth {
  std::unique_ptr<RowWindow> diffuse;  // null when only normals are known
  std::unique_ptr<RowWindow> normals;
  bool normals_encoded = false;     // an 8- or 16-bit normal map: n = 2 v - 1
  std::unique_ptr<RowWindow> mask;  // optional: normal error only where its first channel > 0.5
};

// The truth beside the capture's light file, if any: a `ptmkit synth` set (truth.json,
// truth/diffuse/, truth/normals.exr or .png), or just a normal map `normals.png` (and
// optionally `mask.png`), as the SynthRTI benchmark ships. Headers only: the pixels are read
// band by band with the capture's.
std::optional<Truth> open_truth(const fs::path& lp, const Capture& cap, int w, int h) {
  const fs::path dir = lp.parent_path();
  Truth t;
  auto open_normals = [&](const fs::path& file) {
    t.normals_encoded = probe_image(file).format != PixelFormat::kF32;
    t.normals = std::make_unique<RowWindow>(std::vector<fs::path>{file});
    if (t.normals->reader().channels() < 3) {
      throw Error(file.string() + ": the normal map has " +
                  std::to_string(t.normals->reader().channels()) + " channels, expected 3");
    }
    require_size(t.normals->reader(), w, h, "the capture's images (normal map)");
  };
  if (!fs::exists(dir / "truth.json")) {
    if (!fs::exists(dir / "normals.png")) return std::nullopt;
    open_normals(dir / "normals.png");
    if (fs::exists(dir / "mask.png")) {
      t.mask = std::make_unique<RowWindow>(std::vector<fs::path>{dir / "mask.png"});
      require_size(t.mask->reader(), w, h, "the capture's images (mask)");
    }
    return t;
  }
  std::vector<fs::path> diffuse;
  for (const fs::path& f : cap.files) {
    const fs::path d = dir / "truth" / "diffuse" / f.filename();
    if (!fs::exists(d)) {
      throw Error(d.string() + ": missing diffuse truth (" + (dir / "truth.json").string() +
                  " says this is a synthetic capture)");
    }
    diffuse.push_back(d);
  }
  t.diffuse = std::make_unique<RowWindow>(diffuse);
  require_size(t.diffuse->reader(), w, h, "the capture's images (diffuse truth)");
  const fs::path exr = dir / "truth" / "normals.exr";
  const fs::path png = dir / "truth" / "normals.png";
  if (fs::exists(exr)) {
    open_normals(exr);
  } else if (fs::exists(png)) {
    open_normals(png);
  } else {
    throw Error(exr.string() + ": missing true normals (nor normals.png beside it)");
  }
  return t;
}

// Rows [first, first + count) of each image.
std::vector<Image> rows_of(const std::vector<Image>& images, int first, int count) {
  std::vector<Image> out;
  out.reserve(images.size());
  for (const Image& img : images) {
    out.emplace_back(img.width(), count, img.channels(), img.colour_space());
    std::copy_n(img.row(first), static_cast<std::size_t>(img.width()) * img.channels() * count,
                out.back().row(0));
  }
  return out;
}

// Rows of a capture held at a time: about 256 MiB of float samples over every stack read
// together (capture, test set, diffuse truth), at least 16 rows.
int band_rows(int width, int height, int channels, std::size_t images) {
  const std::size_t per_row = static_cast<std::size_t>(width) * static_cast<std::size_t>(channels) *
                              sizeof(float) * std::max<std::size_t>(images, 1);
  const auto rows = static_cast<int>(
      std::min<std::size_t>(static_cast<std::size_t>(height),
                            (std::size_t{256} << 20) / std::max<std::size_t>(per_row, 1)));
  return std::min(height, std::max(rows, 16));
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
  if (band_rows < 0) return "band_rows must be >= 0 (0 = by memory)";
  return robust.validate();
}

CompareReport compare_solvers(const fs::path& capture_lp, const std::optional<fs::path>& test_lp,
                              const CompareOptions& options) {
  if (const auto err = options.validate(); !err.empty()) throw Error("compare: " + err);
  CompareReport report;
  report.capture = capture_lp;
  Capture cap = open_capture(capture_lp);
  const StackReader& in = cap.rows->reader();
  const int w = in.width();
  const int h = in.height();
  report.width = w;
  report.height = h;
  report.channels = in.channels();
  report.lights = static_cast<int>(cap.dirs.size());
  report.condition_number = fit::analyse_design(cap.dirs, options.design).condition_number;
  std::optional<Capture> test;
  if (test_lp) {
    report.test = *test_lp;
    test = open_capture(*test_lp);
    require_size(test->rows->reader(), w, h,
                 "the images of " + capture_lp.string() + " (the capture fitted)");
    report.test_lights = static_cast<int>(test->dirs.size());
  } else {
    if (options.folds > report.lights) {
      throw Error("compare: " + std::to_string(options.folds) + " folds but " +
                  capture_lp.string() + " has only " + std::to_string(report.lights) + " lights");
    }
    report.folds = options.folds;
    report.test_lights = report.lights;
  }
  std::optional<Truth> truth = open_truth(capture_lp, cap, w, h);
  report.has_truth = truth.has_value() && truth->diffuse != nullptr;
  report.has_normals = truth.has_value();
  const std::size_t ns = options.solvers.size();
  report.results.resize(ns);
  std::vector<HeldOutScore> held(ns);
  std::vector<TruthPsnr> truth_psnr(ns);
  std::vector<OutlierScores> outliers(ns);
  std::vector<std::vector<double>> normal_angles(ns);
  std::vector<std::uint64_t> samples(ns), shadows(ns), highlights(ns);
  const std::vector<Fold> folds =
      test ? std::vector<Fold>{} : kfold_splits(report.lights, options.folds);

  // Band by band: every solver's timing fit, truth scores and held-out predictions over the
  // band's rows, so only a band of each stack is in memory. The SSIM window needs 5 rows
  // around the rows scored: the held-out fits cover them too.
  const int halo = options.ssim ? 5 : 0;
  const std::size_t stacked =
      cap.dirs.size() * (report.has_truth ? 2 : 1) + (test ? test->dirs.size() : 0);
  const int rows = options.band_rows > 0 ? std::min(options.band_rows, h)
                                         : band_rows(w, h, report.channels, stacked);
  for (int y0 = 0; y0 < h; y0 += rows) {
    const int core = std::min(rows, h - y0);
    const int lo = std::max(0, y0 - halo);
    const int hi = std::min(h, y0 + core + halo);
    cap.rows->move_to(lo, hi);
    if (test) test->rows->move_to(lo, hi);
    const std::vector<Image>& window = cap.rows->images();
    const std::vector<Image> band = halo > 0 ? rows_of(window, y0 - lo, core) : window;
    std::vector<Image> diffuse;
    Image normals;
    Image mask;
    if (truth) {
      if (truth->diffuse) {
        truth->diffuse->move_to(y0, y0 + core);
        diffuse = truth->diffuse->images();
      }
      truth->normals->move_to(y0, y0 + core);
      normals = truth->normals->images().front();
      if (truth->normals_encoded) {
        for (std::size_t i = 0; i < normals.size(); ++i) {
          normals.data()[i] = 2.0f * normals.data()[i] - 1.0f;
        }
      }
      if (truth->mask) {
        truth->mask->move_to(y0, y0 + core);
        mask = truth->mask->images().front();
      }
    }

    for (std::size_t k = 0; k < ns; ++k) {
      const Solver s = options.solvers[k];
      SolverResult& r = report.results[k];
      r.solver = s;
      double fit_seconds = 0.0;
      double wall_seconds = 0.0;
      for (int rep = 0; rep < options.timing_repeats; ++rep) {
        CoefficientMap map;
        CoefficientMapSink sink(&map);
        const FitReport fr = fit::fit_images(band, cap.dirs, base_options(options, s), sink);
        if (rep == 0 || fr.fit_seconds < fit_seconds) {
          fit_seconds = fr.fit_seconds;
          wall_seconds = fr.total_seconds;
        }
        report.threads = fr.threads;
        if (rep == 0) {
          samples[k] += fr.outliers.samples;
          shadows[k] += fr.outliers.shadows;
          highlights[k] += fr.outliers.highlights;
        }
      }
      r.fit_seconds += fit_seconds;
      r.wall_seconds += wall_seconds;
      if (test) {
        CoefficientMap map;
        CoefficientMapSink sink(&map);
        (void)fit::fit_images(window, cap.dirs, base_options(options, s), sink);
        const std::vector<Image>& observed = test->rows->images();
        for (std::size_t i = 0; i < test->dirs.size(); ++i) {
          held[k].add_rows(map, test->dirs[i], observed[i], test->integer, options.ssim, y0 - lo,
                           y0 - lo + core);
        }
      }
      if (truth) {
        FitOutputs out;
        out.want_labels = report.has_truth;
        out.want_normals = true;
        CoefficientMap tmap;
        CoefficientMapSink sink(&tmap);
        (void)fit::fit_images(band, cap.dirs, base_options(options, s), sink, &out);
        append_normal_angles(out.normals, normals, mask.empty() ? nullptr : &mask,
                             &normal_angles[k]);
        if (report.has_truth) {
          truth_psnr[k].add(psnr_against_truth(tmap, cap.dirs, diffuse, normals));
          outliers[k].add(outlier_scores(out.labels, band, diffuse, cap.dirs, normals, true));
        }
      }
    }

    // Folds outermost: one training set at a time, shared by every solver.
    for (std::size_t f = 0; f < folds.size(); ++f) {
      const Fold& fold = folds[f];
      std::vector<Image> train;
      std::vector<Eigen::Vector3d> train_dirs;
      for (int i : fold.train) {
        train.push_back(window[static_cast<std::size_t>(i)]);
        train_dirs.push_back(cap.dirs[static_cast<std::size_t>(i)]);
      }
      for (std::size_t k = 0; k < ns; ++k) {
        CoefficientMap map;
        CoefficientMapSink sink(&map);
        try {
          (void)fit::fit_images(train, train_dirs, base_options(options, options.solvers[k]), sink);
        } catch (const Error& e) {
          throw Error(capture_lp.string() + ": fold " + std::to_string(f + 1) + " of " +
                      std::to_string(folds.size()) + " (lights i with i mod " +
                      std::to_string(folds.size()) + " = " + std::to_string(f) +
                      " held out) cannot be fitted: " + e.what());
        }
        for (int i : fold.test) {
          const auto u = static_cast<std::size_t>(i);
          held[k].add_rows(map, cap.dirs[u], window[u], cap.integer, options.ssim, y0 - lo,
                           y0 - lo + core);
        }
      }
    }
  }

  const double texels = static_cast<double>(w) * h;
  for (std::size_t k = 0; k < ns; ++k) {
    SolverResult& r = report.results[k];
    r.us_per_texel = 1e6 * r.fit_seconds / texels;
    r.mtexels_per_second = r.wall_seconds > 0 ? texels / r.wall_seconds / 1e6 : 0.0;
    const double total = std::max(1.0, static_cast<double>(samples[k]));
    r.shadow_fraction = static_cast<double>(shadows[k]) / total;
    r.highlight_fraction = static_cast<double>(highlights[k]) / total;
    if (truth) {
      r.normals = normal_error_of(std::move(normal_angles[k]));
      if (report.has_truth) {
        r.truth_psnr_db = truth_psnr[k].psnr_db;
        r.outliers = outliers[k];
      }
    }
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
