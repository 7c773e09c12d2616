#include "ptmkit/texture/relight.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>

#include "ptmkit/core/atomic_file.h"
#include "ptmkit/core/error.h"

namespace fs = std::filesystem;

namespace ptmkit::texture {

namespace {
Image relight_basis(const CoefficientMap& map, const Eigen::Vector3d& l,
                    const RelightOptions& options);
}  // namespace

Eigen::Vector3d normalised_light(const Eigen::Vector3d& light_dir) {
  const double n = light_dir.norm();
  if (!light_dir.allFinite() || !std::isfinite(n) || n == 0.0) {
    std::ostringstream s;
    s << "light direction (" << light_dir.x() << ", " << light_dir.y() << ", " << light_dir.z()
      << ") is not a usable direction (it must be finite and non-zero)";
    throw Error(s.str());
  }
  return light_dir / n;
}

Image relight(const CoefficientMap& map, const Eigen::Vector3d& light_dir,
              const RelightOptions& options) {
  const Eigen::Vector3d l = normalised_light(light_dir);
  if (map.basis != Basis::kPtm) return relight_basis(map, l, options);
  Image out(map.width, map.height, 3, map.colour_space, 0.0f);
  if (l.z() <= 0.0 || out.empty()) return out;  // no light from behind the surface
  tbb::parallel_for(tbb::blocked_range<int>(0, map.height), [&](const tbb::blocked_range<int>& r) {
    for (int y = r.begin(); y < r.end(); ++y) {
      float* row = out.row(y);
      for (int x = 0; x < map.width; ++x) {
        float* rgb = row + 3 * static_cast<std::size_t>(x);
        map.evaluate(x, y, l.x(), l.y(), rgb);
        if (options.clamp) {
          for (int c = 0; c < 3; ++c) rgb[c] = std::clamp(rgb[c], 0.0f, 1.0f);
        }
      }
    }
  });
  return out;
}

namespace {

nlohmann::json number_or_null(double v) {
  return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr);
}

}  // namespace

std::string RelightSetReport::brief() const {
  std::ostringstream s;
  s << entries.size() << " relit images";
  if (compared > 0) {
    s.setf(std::ios::fixed);
    s.precision(2);
    s << "; compared with " << compared << " photos: mean PSNR " << mean_psnr_db
      << " dB, mean abs error " << mean_abs_grey << " grey levels";
  } else {
    s << "; no photo found to compare with";
  }
  return s.str();
}

std::string RelightSetReport::to_json() const {
  nlohmann::json j;
  j["lights"] = nlohmann::json::array();
  for (const auto& e : entries) {
    nlohmann::json l;
    l["output"] = e.output.string();
    l["reference"] = e.reference.string();
    l["light_dir"] = {e.light_dir.x(), e.light_dir.y(), e.light_dir.z()};
    l["compared"] = e.compared;
    if (e.compared) {
      l["psnr_db"] = number_or_null(e.comparison.psnr_db);
      l["mean_abs_grey"] = e.comparison.mean_abs_grey;
      l["max_abs_grey"] = 255.0 * e.comparison.max_abs;
      l["pixels"] = e.comparison.pixels;
    }
    j["lights"].push_back(l);
  }
  j["compared"] = compared;
  j["mean_psnr_db"] = number_or_null(mean_psnr_db);
  j["mean_abs_grey"] = number_or_null(mean_abs_grey);
  return j.dump(2) + "\n";
}

namespace {

// The light-set loop for any texture: `render` relights it at a unit direction.
RelightSetReport relight_set_impl(int map_width, int map_height, ColourSpace map_colour_space,
                                  const std::function<Image(const Eigen::Vector3d&)>& render,
                                  const LightSet& lights, const RelightSetOptions& options) {
  const fs::path set_name = lights.source.empty() ? fs::path("light set") : lights.source;
  if (options.out_dir.empty()) throw Error("relight: no output folder given");
  if (lights.empty()) throw Error(where(set_name) + ": no lights");

  // Check everything before writing anything.
  std::map<fs::path, fs::path> names;  // output -> its light's image
  std::vector<bool> has_photo(lights.size(), false);
  for (std::size_t i = 0; i < lights.size(); ++i) {
    const Light& light = lights.lights[i];
    (void)normalised_light(light.direction);
    const fs::path name = light.image.filename();
    if (name.empty())
      throw Error(where(set_name) + ": light " + std::to_string(i + 1) + " has no image name");
    const fs::path out = options.out_dir / name;
    if (auto [it, fresh] = names.emplace(out, light.image); !fresh) {
      throw Error(where(set_name) + ": " + it->second.string() + " and " + light.image.string() +
                  " would both be written as " + out.string());
    }
    if (!options.report_json.empty() && out == options.report_json) {
      throw Error(where(out) + ": is both a relit image and the report");
    }
    std::error_code ec;
    if (!fs::exists(light.image, ec)) continue;
    const ImageInfo info = probe_image(light.image);
    if (info.width != map_width || info.height != map_height) {
      throw Error(where(light.image) + ": photo is " + std::to_string(info.width) + " x " +
                  std::to_string(info.height) + ", the texture is " + std::to_string(map_width) +
                  " x " + std::to_string(map_height));
    }
    if (info.channels != 1 && info.channels != 3 && info.channels != 4) {
      throw Error(where(light.image) + ": photo has " + std::to_string(info.channels) +
                  " channels; 1, 3 or 4 can be compared");
    }
    if (info.colour_space != map_colour_space) {
      throw Error(where(light.image) + ": photo is " + std::string(to_string(info.colour_space)) +
                  ", the texture is taken as " + std::string(to_string(map_colour_space)) +
                  "; say which colour space the texture holds");
    }
    has_photo[i] = true;
  }
  Image mask;
  if (!options.mask.empty()) {
    mask = read_image(options.mask);
    if (mask.width() != map_width || mask.height() != map_height) {
      throw Error(where(options.mask) + ": mask is " + std::to_string(mask.width()) + " x " +
                  std::to_string(mask.height()) + ", the texture is " + std::to_string(map_width) +
                  " x " + std::to_string(map_height));
    }
  }

  // The folder is committed as a whole: images replace earlier ones only once every image
  // and the report are written; a failure leaves the folder as it was.
  OutputTransaction outputs;
  std::error_code ec;
  if (!fs::exists(options.out_dir, ec)) {
    ensure_directory(options.out_dir);
  } else if (!fs::is_directory(options.out_dir, ec)) {
    throw Error(where(options.out_dir) + ": exists and is not a folder");
  }

  RelightSetReport report;
  double sum_psnr = 0.0, sum_abs = 0.0;
  for (std::size_t i = 0; i < lights.size(); ++i) {
    const Light& light = lights.lights[i];
    RelightSetEntry e;
    e.output = options.out_dir / light.image.filename();
    e.reference = light.image;
    e.light_dir = normalised_light(light.direction);
    const Image relit = render(e.light_dir);
    write_image(e.output, relit.view(), options.write);
    if (has_photo[i]) {
      const Image photo = read_image(light.image);
      try {
        const ConstImageViewF mask_view = mask.view();
        e.comparison =
            compare_images(relit.view(), photo.view(), mask.empty() ? nullptr : &mask_view);
      } catch (const Error& err) {
        throw Error(where(light.image) + ": " + err.what());
      }
      e.compared = true;
      ++report.compared;
      sum_psnr += e.comparison.psnr_db;
      sum_abs += e.comparison.mean_abs_grey;
    }
    report.entries.push_back(std::move(e));
  }
  const double n = static_cast<double>(report.compared);
  report.mean_psnr_db =
      report.compared > 0 ? sum_psnr / n : std::numeric_limits<double>::quiet_NaN();
  report.mean_abs_grey =
      report.compared > 0 ? sum_abs / n : std::numeric_limits<double>::quiet_NaN();
  if (!options.report_json.empty()) {
    write_file_atomic(options.report_json, report.to_json());
    report.report_json = options.report_json;
  }
  outputs.commit();
  return report;
}

}  // namespace

RelightSetReport relight_light_set(const CoefficientMap& map, const LightSet& lights,
                                   const RelightSetOptions& options) {
  return relight_set_impl(
      map.width, map.height, map.colour_space,
      [&](const Eigen::Vector3d& l) { return relight(map, l, options.relight); }, lights, options);
}

namespace {

// A map in another basis than PTM (HSH, rgb layout): the basis at the light, summed per
// channel.
Image relight_basis(const CoefficientMap& map, const Eigen::Vector3d& l,
                    const RelightOptions& options) {
  Image out(map.width, map.height, 3, map.colour_space, 0.0f);
  if (l.z() <= 0.0 || out.empty()) return out;  // no light from behind the surface
  if (map.model != ColourModel::kRGB) {
    throw Error("relight: a " + std::string(to_string(map.basis)) +
                " map is relit in the rgb layout only");
  }
  const int t = map.terms();
  double b[16];
  hsh_basis(t, l, b);
  tbb::parallel_for(tbb::blocked_range<int>(0, map.height), [&](const tbb::blocked_range<int>& r) {
    for (int y = r.begin(); y < r.end(); ++y) {
      float* row = out.row(y);
      for (int x = 0; x < map.width; ++x) {
        const float* c = map.texel_coeffs(x, y);
        float* rgb = row + 3 * static_cast<std::size_t>(x);
        for (int k = 0; k < 3; ++k) {
          double v = 0.0;
          for (int j = 0; j < t; ++j) v += c[k * t + j] * b[j];
          rgb[k] =
              options.clamp ? static_cast<float>(std::clamp(v, 0.0, 1.0)) : static_cast<float>(v);
        }
      }
    }
  });
  return out;
}

}  // namespace

}  // namespace ptmkit::texture
