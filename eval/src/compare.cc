// The comparison itself: solvers fitted and scored band by band over the capture (timing,
// held-out prediction, truth). Its outputs are written by compare_report.cc.
#include "ptmkit/eval/compare.h"

#include <algorithm>
#include <cmath>
#include <memory>
#include <set>

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

// Rows of a capture held at a time: about 64 MiB of float samples over every stack read
// together (capture, test set, diffuse truth), at least 16 rows.
int band_rows(int width, int height, int channels, std::size_t images) {
  const std::size_t per_row = static_cast<std::size_t>(width) * static_cast<std::size_t>(channels) *
                              sizeof(float) * std::max<std::size_t>(images, 1);
  const auto rows = static_cast<int>(
      std::min<std::size_t>(static_cast<std::size_t>(height),
                            (std::size_t{64} << 20) / std::max<std::size_t>(per_row, 1)));
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
  std::vector<NormalAngles> normal_angles(ns);
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
    // The band's own rows: the window itself unless it carries SSIM rows around them.
    std::vector<Image> trimmed;
    if (lo != y0 || hi != y0 + core) trimmed = rows_of(window, y0 - lo, core);
    const std::vector<Image>& band = trimmed.empty() ? window : trimmed;
    static const std::vector<Image> kNone;
    const std::vector<Image>* diffuse_rows = &kNone;
    Image normals;
    Image mask;
    if (truth) {
      if (truth->diffuse) {
        truth->diffuse->move_to(y0, y0 + core);
        diffuse_rows = &truth->diffuse->images();
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
        normal_angles[k].add(out.normals, normals, mask.empty() ? nullptr : &mask);
        if (report.has_truth) {
          truth_psnr[k].add(psnr_against_truth(tmap, cap.dirs, *diffuse_rows, normals));
          outliers[k].add(outlier_scores(out.labels, band, *diffuse_rows, cap.dirs, normals, true));
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
      r.normals = normal_angles[k].result();
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

}  // namespace ptmkit::eval
