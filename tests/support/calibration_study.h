// How light-calibration error carries into a fit: a relief is rendered under known lights,
// the lights are calibrated from rendered sphere photographs (or perturbed on purpose), the
// relief is fitted with each light set, and the fits are relit at held-out directions and
// scored against the diffuse truth. Shared by bench/calibration_effect.cc (the figures in
// docs/CALIBRATION.md) and tests/calib_effect_test.cc.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "ptmkit/calib/dome.h"
#include "ptmkit/calib/sphere.h"
#include "ptmkit/core/coefficients.h"
#include "ptmkit/eval/truth.h"
#include "ptmkit/fit/fit.h"
#include "ptmkit/synth/rig.h"
#include "ptmkit/synth/synth.h"

namespace ptmkit::study {

inline double angle_deg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::acos(std::clamp(a.normalized().dot(b.normalized()), -1.0, 1.0)) * 180.0 /
         std::numbers::pi;
}

struct AngleStats {
  double mean_deg = 0.0;
  double max_deg = 0.0;
};

inline AngleStats angle_stats(const std::vector<Eigen::Vector3d>& a,
                              const std::vector<Eigen::Vector3d>& b) {
  AngleStats s;
  for (std::size_t i = 0; i < a.size(); ++i) {
    const double d = angle_deg(a[i], b[i]);
    s.mean_deg += d / static_cast<double>(a.size());
    s.max_deg = std::max(s.max_deg, d);
  }
  return s;
}

// Lights calibrated from one rendered orthographic sphere photograph per light: radius
// `radius_px`, a light of 1 degree angular radius whose reflection is 8 times full scale (it
// clips, as a dome LED's does: a dim sub-pixel highlight on a small sphere would not be
// found), 8-bit quantised, Gaussian noise `noise_grey`; the sphere is found
// automatically, as a user would run `ptmkit calibrate sphere`. A light without a usable
// highlight keeps a NaN direction (the caller checks).
inline std::vector<Eigen::Vector3d> sphere_calibrated(const std::vector<Eigen::Vector3d>& truth,
                                                      double radius_px, double noise_grey,
                                                      std::uint64_t seed) {
  synth::SphereRigOptions rig;
  const int side = static_cast<int>(std::ceil(2.0 * radius_px)) + 60;
  rig.width = side;
  rig.height = side;
  rig.centre_px = {0.5 * (side - 1) + 0.3, 0.5 * (side - 1) - 0.2};  // off the pixel grid
  rig.radius_px = radius_px;
  rig.noise_grey = noise_grey;
  rig.supersample = 3;
  rig.light_radius_deg = 1.0;
  rig.highlight = 8.0;
  std::vector<Image> images;
  std::vector<std::filesystem::path> names;
  for (std::size_t i = 0; i < truth.size(); ++i) {
    rig.light_dir = truth[i];
    rig.seed = seed + i;
    Image im = synth::render_sphere_rig(rig);
    float* px = im.data();
    for (std::size_t k = 0; k < im.size(); ++k) {
      px[k] = std::round(std::clamp(px[k], 0.0f, 1.0f) * 255.0f) / 255.0f;
    }
    images.push_back(std::move(im));
    names.emplace_back("sphere_" + std::to_string(i) + ".png");
  }
  const calib::SphereReport report = calib::calibrate_sphere(images, names, {});
  std::vector<Eigen::Vector3d> out;
  for (const auto& l : report.lights) {
    out.push_back(l.found ? l.direction : Eigen::Vector3d::Constant(std::nan("")));
  }
  return out;
}

// Each direction turned by exactly `deg` about a random axis perpendicular to it (kept above
// the horizon).
inline std::vector<Eigen::Vector3d> perturbed_random(const std::vector<Eigen::Vector3d>& truth,
                                                     double deg, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> angle(0.0, 2.0 * std::numbers::pi);
  std::vector<Eigen::Vector3d> out;
  for (const auto& d : truth) {
    const Eigen::Vector3d u = d.unitOrthogonal();
    const Eigen::Vector3d w = d.cross(u);
    Eigen::Vector3d r;
    do {
      const double phi = angle(rng);
      const Eigen::Vector3d axis = std::cos(phi) * u + std::sin(phi) * w;
      r = Eigen::AngleAxisd(deg * std::numbers::pi / 180.0, axis) * d;
    } while (r.z() <= 0.02);
    out.push_back(r.normalized());
  }
  return out;
}

// Every direction turned by `deg` about the image's x axis: one systematic error (a dome or
// camera tilted by that much).
inline std::vector<Eigen::Vector3d> perturbed_tilt(const std::vector<Eigen::Vector3d>& truth,
                                                   double deg) {
  const Eigen::AngleAxisd tilt(deg * std::numbers::pi / 180.0, Eigen::Vector3d::UnitX());
  std::vector<Eigen::Vector3d> out;
  for (const auto& d : truth) {
    Eigen::Vector3d r = tilt * d;
    if (r.z() <= 0.02) r = d;  // the zenith-most tilt of a horizon light would go below
    out.push_back(r.normalized());
  }
  return out;
}

// A rendered relief under the capture lights, and its diffuse truth at held-out lights.
struct Capture {
  synth::SynthOptions options;
  synth::Scene scene;
  std::vector<Eigen::Vector3d> lights;
  std::vector<Image> observed;
  std::vector<Eigen::Vector3d> test_lights;
  std::vector<Image> test_diffuse;
};

inline Capture render_capture(const std::string& preset, int size,
                              const std::vector<Eigen::Vector3d>& lights,
                              const std::vector<Eigen::Vector3d>& test_lights) {
  Capture c;
  c.options = synth::preset_options(preset);
  c.options.width = size;
  c.options.height = size;
  c.scene = synth::build_scene(c.options);
  c.lights = lights;
  c.test_lights = test_lights;
  for (std::size_t i = 0; i < lights.size(); ++i) {
    c.observed.push_back(
        synth::render_light(c.scene, c.options, lights[i], static_cast<int>(i)).observed);
  }
  for (std::size_t i = 0; i < test_lights.size(); ++i) {
    c.test_diffuse.push_back(
        synth::render_light(c.scene, c.options, test_lights[i], static_cast<int>(1000 + i))
            .diffuse);
  }
  return c;
}

inline CoefficientMap fit_with(const Capture& c, const std::vector<Eigen::Vector3d>& dirs) {
  fit::FitOptions o;
  o.threads = 1;
  o.residual_stats = false;
  CoefficientMap map;
  CoefficientMapSink sink(&map);
  (void)fit::fit_images(c.observed, dirs, o, sink);
  return map;
}

struct RelightScore {
  double psnr_db = 0.0;         // against the diffuse truth at the held-out lights (lit samples)
  double mean_change_grey = 0;  // mean |relit - relit with the true lights|, grey levels
};

inline RelightScore score(const Capture& c, const CoefficientMap& fit,
                          const CoefficientMap& reference) {
  RelightScore s;
  s.psnr_db = eval::psnr_against_truth(fit, c.test_lights, c.test_diffuse, c.scene.normals).psnr_db;
  double sum = 0.0;
  std::uint64_t n = 0;
  for (const auto& l : c.test_lights) {
    for (int y = 0; y < fit.height; ++y) {
      for (int x = 0; x < fit.width; ++x) {
        if (!eval::is_lit(c.scene.normals, x, y, l)) continue;
        float a[3], b[3];
        fit.evaluate(x, y, l.x(), l.y(), a);
        reference.evaluate(x, y, l.x(), l.y(), b);
        for (int k = 0; k < 3; ++k) sum += std::abs(static_cast<double>(a[k]) - b[k]);
        n += 3;
      }
    }
  }
  s.mean_change_grey = n ? 255.0 * sum / static_cast<double>(n) : 0.0;
  return s;
}

}  // namespace ptmkit::study
