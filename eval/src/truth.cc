#include "ptmkit/eval/truth.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>
#include <vector>

#include "ptmkit/core/colour.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/holdout.h"

namespace ptmkit::eval {

namespace {

void require_same_size(const Image& a, int w, int h, const char* what) {
  if (a.width() != w || a.height() != h) {
    throw Error(std::string("evaluate: ") + what + " is " + std::to_string(a.width()) + "x" +
                std::to_string(a.height()) + ", expected " + std::to_string(w) + "x" +
                std::to_string(h));
  }
}

double sample_luma(const Image& img, int x, int y) {
  if (img.channels() >= 3) return luma(img.at(x, y, 0), img.at(x, y, 1), img.at(x, y, 2));
  return img.at(x, y, 0);
}

}  // namespace

bool is_lit(const Image& truth_normals, int x, int y, const Eigen::Vector3d& light) {
  const Eigen::Vector3d n(truth_normals.at(x, y, 0), truth_normals.at(x, y, 1),
                          truth_normals.at(x, y, 2));
  return n.dot(light.normalized()) > 0.0;
}

TruthPsnr psnr_against_truth(const CoefficientMap& fit,
                             const std::vector<Eigen::Vector3d>& light_dirs,
                             const std::vector<Image>& diffuse, const Image& normals) {
  if (diffuse.size() != light_dirs.size())
    throw Error("evaluate: truth and lights differ in count");
  require_same_size(normals, fit.width, fit.height, "the normal map");
  TruthPsnr out;
  double sum = 0.0;
  for (std::size_t i = 0; i < light_dirs.size(); ++i) {
    const Image& t = diffuse[i];
    require_same_size(t, fit.width, fit.height, "a diffuse truth image");
    const Eigen::Vector3d l = light_dirs[i].normalized();
    const int ch = std::min(t.channels(), 3);
    for (int y = 0; y < fit.height; ++y) {
      for (int x = 0; x < fit.width; ++x) {
        if (!is_lit(normals, x, y, l)) continue;
        float rgb[3];
        fit.evaluate(x, y, l.x(), l.y(), rgb);
        for (int c = 0; c < ch; ++c) {
          const double d = static_cast<double>(rgb[c]) - t.at(x, y, c);
          sum += d * d;
          ++out.samples;
        }
      }
    }
  }
  out.sum_sq = sum;
  const double mse = out.samples > 0 ? sum / static_cast<double>(out.samples) : 0.0;
  out.psnr_db = psnr_db(mse);
  return out;
}

void TruthPsnr::add(const TruthPsnr& band) {
  sum_sq += band.sum_sq;
  samples += band.samples;
  psnr_db = ptmkit::psnr_db(samples > 0 ? sum_sq / static_cast<double>(samples) : 0.0);
}

namespace {

void finish(OutlierScores* s) {
  s->precision =
      s->labelled > 0 ? static_cast<double>(s->hits) / static_cast<double>(s->labelled) : 1.0;
  s->recall = s->true_outliers > 0
                  ? static_cast<double>(s->hits) / static_cast<double>(s->true_outliers)
                  : 1.0;
}

}  // namespace

void OutlierScores::add(const OutlierScores& band) {
  true_outliers += band.true_outliers;
  labelled += band.labelled;
  samples += band.samples;
  hits += band.hits;
  finish(this);
}

OutlierScores outlier_scores(const std::vector<std::uint8_t>& labels,
                             const std::vector<Image>& observed, const std::vector<Image>& diffuse,
                             const std::vector<Eigen::Vector3d>& light_dirs, const Image& normals,
                             bool lit_only, double threshold_grey) {
  const std::size_t n = light_dirs.size();
  if (observed.size() != n || diffuse.size() != n || n == 0) {
    throw Error("evaluate: observed, truth and lights differ in count");
  }
  const int w = normals.width();
  const int h = normals.height();
  if (labels.size() != static_cast<std::size_t>(w) * static_cast<std::size_t>(h) * n) {
    throw Error("evaluate: the label dump does not match the image size and light count");
  }
  OutlierScores s;
  for (std::size_t i = 0; i < n; ++i) {
    require_same_size(observed[i], w, h, "an observed image");
    require_same_size(diffuse[i], w, h, "a diffuse truth image");
    const Eigen::Vector3d l = light_dirs[i].normalized();
    for (int y = 0; y < h; ++y) {
      for (int x = 0; x < w; ++x) {
        if (lit_only && !is_lit(normals, x, y, l)) continue;
        ++s.samples;
        const double d = 255.0 * (sample_luma(observed[i], x, y) - sample_luma(diffuse[i], x, y));
        const bool truth = std::abs(d) > threshold_grey;
        const bool flagged = labels[(static_cast<std::size_t>(y) * w + x) * n + i] != 0;
        s.true_outliers += truth ? 1 : 0;
        s.labelled += flagged ? 1 : 0;
        s.hits += truth && flagged ? 1 : 0;
      }
    }
  }
  finish(&s);
  return s;
}

NormalAngles::NormalAngles()
    : bins_(static_cast<std::size_t>(std::lround(180.0 / kBinDeg)) + 1, 0) {}

void NormalAngles::add(const Image& estimated, const Image& truth, const Image* mask) {
  require_same_size(estimated, truth.width(), truth.height(), "the estimated normal map");
  if (estimated.channels() < 3 || truth.channels() < 3)
    throw Error("evaluate: normal maps need 3 channels");
  if (mask != nullptr) require_same_size(*mask, truth.width(), truth.height(), "the mask");
  for (int y = 0; y < truth.height(); ++y) {
    for (int x = 0; x < truth.width(); ++x) {
      if (mask != nullptr && !(mask->at(x, y, 0) > 0.5f)) continue;
      Eigen::Vector3d a(estimated.at(x, y, 0), estimated.at(x, y, 1), estimated.at(x, y, 2));
      Eigen::Vector3d b(truth.at(x, y, 0), truth.at(x, y, 1), truth.at(x, y, 2));
      if (a.norm() < 1e-12 || b.norm() < 1e-12) continue;
      const double c = std::clamp(a.normalized().dot(b.normalized()), -1.0, 1.0);
      const double deg = std::acos(c) * 180.0 / M_PI;
      sum_deg_ += deg;
      ++count_;
      const auto bin = static_cast<std::size_t>(deg / kBinDeg);
      ++bins_[std::min(bin, bins_.size() - 1)];
    }
  }
}

NormalError NormalAngles::result() const {
  NormalError e;
  e.texels = count_;
  if (count_ == 0) return e;
  e.mean_deg = sum_deg_ / static_cast<double>(count_);
  // The value of rank count / 2 (0-based), as the exact median took it.
  const std::uint64_t rank = count_ / 2;
  std::uint64_t below = 0;
  for (std::size_t i = 0; i < bins_.size(); ++i) {
    if (below + bins_[i] > rank) {
      const double within =
          (static_cast<double>(rank - below) + 0.5) / static_cast<double>(bins_[i]);
      e.median_deg = (static_cast<double>(i) + within) * kBinDeg;
      break;
    }
    below += bins_[i];
  }
  return e;
}

NormalError normal_error(const Image& estimated, const Image& truth, const Image* mask) {
  NormalAngles angles;
  angles.add(estimated, truth, mask);
  return angles.result();
}

}  // namespace ptmkit::eval
