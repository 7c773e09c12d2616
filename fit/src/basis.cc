#include "ptmkit/fit/basis.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>

#include <Eigen/SVD>
#include <nlohmann/json.hpp>

#include "ptmkit/core/colour.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/hsh.h"
#include "ptmkit/core/stack_reader.h"

namespace ptmkit::fit {

std::string_view to_string(Basis basis) {
  switch (basis) {
    case Basis::kHsh2:
      return "hsh2";
    case Basis::kPtm:
      return "ptm";
    case Basis::kHsh3:
      return "hsh3";
    case Basis::kHsh4:
      return "hsh4";
  }
  return "?";
}

Basis parse_basis(std::string_view name) {
  for (Basis b : all_bases()) {
    if (name == to_string(b)) return b;
  }
  throw Error("unknown basis '" + std::string(name) + "' (known: hsh2, ptm, hsh3, hsh4)");
}

int basis_terms(Basis basis) {
  switch (basis) {
    case Basis::kHsh2:
      return 4;
    case Basis::kPtm:
      return kPtmTerms;
    case Basis::kHsh3:
      return 9;
    case Basis::kHsh4:
      return 16;
  }
  return 0;
}

bool is_hsh(Basis basis) { return basis != Basis::kPtm; }

std::vector<Basis> all_bases() { return {Basis::kHsh2, Basis::kPtm, Basis::kHsh3, Basis::kHsh4}; }

void evaluate_basis(Basis basis, const Eigen::Vector3d& dir, double* out) {
  if (basis == Basis::kPtm) {
    const auto b = ptm_basis(dir.x(), dir.y());
    std::copy(b.begin(), b.end(), out);
    return;
  }
  ptmkit::hsh_basis(basis_terms(basis), dir, out);
}

Eigen::MatrixXd basis_matrix(Basis basis, const std::vector<Eigen::Vector3d>& dirs) {
  const int t = basis_terms(basis);
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> a(
      static_cast<Eigen::Index>(dirs.size()), t);
  for (std::size_t i = 0; i < dirs.size(); ++i) {
    evaluate_basis(basis, dirs[i].normalized(), a.data() + i * static_cast<std::size_t>(t));
  }
  return a;
}

BasisDesign BasisDesign::build(Basis basis, const std::vector<Eigen::Vector3d>& dirs,
                               const DesignOptions& options) {
  BasisDesign d;
  d.basis = basis;
  const int t = basis_terms(basis);
  const auto n = static_cast<int>(dirs.size());
  const std::string name(to_string(basis));
  if (n < t) {
    throw Error("basis " + name + " has " + std::to_string(t) + " terms but the layout has " +
                std::to_string(n) + " lights: use a basis with fewer terms");
  }
  d.design = basis_matrix(basis, dirs);
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(d.design, Eigen::ComputeThinU | Eigen::ComputeThinV);
  const Eigen::VectorXd sv = svd.singularValues();
  const double smallest = sv(sv.size() - 1);
  d.condition_number = smallest > 0 ? sv(0) / smallest : std::numeric_limits<double>::infinity();
  const double lambda = options.ridge_lambda * n;
  if (options.ridge_lambda <= 0 && !(d.condition_number <= options.max_condition)) {
    char buf[256];
    std::snprintf(buf, sizeof buf,
                  "basis %s: the light layout is too ill-conditioned for %d terms (cond(A) "
                  "%.3g > %.3g): use a basis with fewer terms, more lights, or --ridge",
                  name.c_str(), t, d.condition_number, options.max_condition);
    throw Error(buf);
  }
  // P = V diag(s / (s^2 + lambda)) U^T: the (ridge) least-squares solution by SVD.
  Eigen::VectorXd inv(sv.size());
  for (Eigen::Index i = 0; i < sv.size(); ++i) {
    const double den = sv(i) * sv(i) + lambda;
    inv(i) = den > 0 ? sv(i) / den : 0.0;
  }
  d.pseudo_inverse = svd.matrixV() * inv.asDiagonal() * svd.matrixU().transpose();
  return d;
}

void BasisMap::evaluate(int x, int y, const Eigen::Vector3d& dir, float rgb[3]) const {
  double b[16];
  evaluate_basis(basis, dir, b);
  const int t = terms();
  const float* c = coeffs.data() + (static_cast<std::size_t>(y) * width + x) * 3 * t;
  for (int k = 0; k < 3; ++k) {
    double v = 0.0;
    for (int j = 0; j < t; ++j) v += c[k * t + j] * b[j];
    rgb[k] = static_cast<float>(v);
  }
}

std::string BasisFitOptions::validate() const {
  if (model == ColourModel::kYCC) {
    return "the ycc colour model is only available with the PTM basis: use rgb or lrgb";
  }
  if (band_rows < 1) return "band_rows must be at least 1";
  if (threads < 0) return "threads must be 0 (all cores) or positive";
  if (!(design.ridge_lambda >= 0)) return "ridge_lambda must be >= 0";
  return {};
}

std::string BasisFitReport::to_json() const {
  nlohmann::json j;
  j["lights"] = lights;
  j["width"] = width;
  j["height"] = height;
  j["channels"] = channels;
  j["basis"] = std::string(to_string(basis));
  j["terms"] = basis_terms(basis);
  j["model"] = std::string(ptmkit::to_string(model));
  j["colour_space"] = std::string(ptmkit::to_string(colour_space));
  j["condition_number"] = condition_number;
  j["residuals"] = {{"rms_grey", residual_rms_grey},
                    {"max_abs_grey", residual_max_abs_grey},
                    {"samples", residual_samples}};
  j["total_seconds"] = total_seconds;
  return j.dump(2);
}

namespace {

// Per-row residual sums, merged in row order (deterministic).
struct RowResidual {
  double sum_sq = 0.0;
  double max_abs = 0.0;
  std::uint64_t count = 0;
};

// Fits one band into out->coeffs rows [band.y0, band.y0 + band.rows).
void fit_band(const StackBand& band, const BasisDesign& d, ColourModel model, BasisMap* out,
              RowResidual* total) {
  const int n = band.images;
  const int t = basis_terms(d.basis);
  const int ch = band.channels;
  const int w = band.width;
  const bool lum = model == ColourModel::kLRGB || ch != 3;
  std::vector<RowResidual> rows(static_cast<std::size_t>(band.rows));
  tbb::parallel_for(0, band.rows, [&](int r) {
    Eigen::VectorXd v(n), c(t), pred(n);
    Eigen::MatrixXd rgb(n, 3);
    RowResidual& res = rows[static_cast<std::size_t>(r)];
    for (int x = 0; x < w; ++x) {
      float* dst =
          out->coeffs.data() + (static_cast<std::size_t>(band.y0 + r) * out->width + x) * 3 * t;
      for (int i = 0; i < n; ++i) {
        for (int k = 0; k < 3; ++k) rgb(i, k) = band.sample(i, r, x, ch == 3 ? k : 0);
      }
      if (lum) {
        double yy = 0.0, yc[3] = {0, 0, 0};
        for (int i = 0; i < n; ++i) {
          v(i) = ch == 3 ? luma(rgb(i, 0), rgb(i, 1), rgb(i, 2)) : rgb(i, 0);
          yy += v(i) * v(i);
          for (int k = 0; k < 3; ++k) yc[k] += v(i) * rgb(i, k);
        }
        c.noalias() = d.pseudo_inverse * v;
        // Least-squares colour (fit.h's LRGB); grey input gives (1, 1, 1).
        for (int k = 0; k < 3; ++k) {
          const double kc = yy > 1e-20 ? std::max(0.0, yc[k] / yy) : 1.0;
          for (int j = 0; j < t; ++j) dst[k * t + j] = static_cast<float>(kc * c(j));
        }
      } else {
        for (int k = 0; k < 3; ++k) {
          c.noalias() = d.pseudo_inverse * rgb.col(k);
          for (int j = 0; j < t; ++j) dst[k * t + j] = static_cast<float>(c(j));
        }
      }
      for (int k = 0; k < (ch == 3 ? 3 : 1); ++k) {
        for (int j = 0; j < t; ++j) c(j) = dst[k * t + j];
        pred.noalias() = d.design * c;
        for (int i = 0; i < n; ++i) {
          const double e = 255.0 * (pred(i) - rgb(i, k));
          res.sum_sq += e * e;
          res.max_abs = std::max(res.max_abs, std::abs(e));
          ++res.count;
        }
      }
    }
  });
  for (const RowResidual& r : rows) {
    total->sum_sq += r.sum_sq;
    total->max_abs = std::max(total->max_abs, r.max_abs);
    total->count += r.count;
  }
}

template <class NextBand>
BasisFitReport run_fit(const std::vector<Eigen::Vector3d>& dirs, int width, int height,
                       int channels, ColourSpace colour_space, const BasisFitOptions& options,
                       BasisMap* out, NextBand next_band) {
  const auto start = std::chrono::steady_clock::now();
  if (const std::string problem = options.validate(); !problem.empty()) throw Error(problem);
  const BasisDesign d = BasisDesign::build(options.basis, dirs, options.design);
  BasisFitReport report;
  report.lights = static_cast<int>(dirs.size());
  report.width = width;
  report.height = height;
  report.channels = channels;
  report.basis = options.basis;
  report.model = channels == 3 ? options.model : ColourModel::kLRGB;
  report.colour_space = colour_space;
  report.condition_number = d.condition_number;
  out->width = width;
  out->height = height;
  out->basis = options.basis;
  out->colour_space = colour_space;
  out->coeffs.assign(static_cast<std::size_t>(width) * height * 3 * basis_terms(options.basis),
                     0.0f);
  const ThreadLimit limit(options.threads);
  StackBand band;
  RowResidual total;
  while (next_band(&band)) {
    fit_band(band, d, options.model, out, &total);
    if (options.progress) {
      options.progress(static_cast<double>(band.y0 + band.rows) / std::max(1, height));
    }
  }
  report.residual_samples = total.count;
  report.residual_rms_grey =
      total.count ? std::sqrt(total.sum_sq / static_cast<double>(total.count)) : 0.0;
  report.residual_max_abs_grey = total.max_abs;
  report.total_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return report;
}

}  // namespace

BasisFitReport fit_basis_capture(const LightSet& lights, const BasisFitOptions& options,
                                 BasisMap* out) {
  StackReader reader(lights.images(), options.input);
  const int rows = std::max(1, options.band_rows);
  return run_fit(lights.directions(), reader.width(), reader.height(), reader.channels(),
                 reader.info().colour_space, options, out,
                 [&](StackBand* band) { return reader.read_band(rows, band); });
}

BasisFitReport fit_basis_images(const std::vector<Image>& images,
                                const std::vector<Eigen::Vector3d>& dirs,
                                const BasisFitOptions& options, BasisMap* out) {
  if (images.empty() || images.size() != dirs.size()) {
    throw Error("fit_basis_images: one image per direction is needed");
  }
  const int w = images[0].width();
  const int h = images[0].height();
  const int ch = images[0].channels();
  for (const Image& im : images) {
    if (im.width() != w || im.height() != h || im.channels() != ch) {
      throw Error("fit_basis_images: the images differ in size or channels");
    }
  }
  const int rows = std::max(1, options.band_rows);
  int y = 0;
  return run_fit(dirs, w, h, ch, images[0].colour_space(), options, out, [&](StackBand* band) {
    if (y >= h) return false;
    band->y0 = y;
    band->rows = std::min(rows, h - y);
    band->width = w;
    band->channels = ch;
    band->images = static_cast<int>(images.size());
    band->samples.resize(band->image_stride() * images.size());
    for (std::size_t i = 0; i < images.size(); ++i) {
      std::copy_n(images[i].row(y), band->image_stride(), band->image(static_cast<int>(i)));
    }
    y += band->rows;
    return true;
  });
}

}  // namespace ptmkit::fit
