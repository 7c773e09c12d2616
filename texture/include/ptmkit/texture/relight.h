// Relighting a coefficient map: the image the texture shows under a given light.
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "ptmkit/core/coefficients.h"
#include "ptmkit/core/image.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/core/light_set.h"
#include "ptmkit/texture/metrics.h"
#include "ptmkit/texture/rti.h"

namespace ptmkit::texture {

struct RelightOptions {
  // Clamp the output to [0, 1] (what a display or an integer file shows). Off keeps the
  // polynomial's raw values, which may be negative or exceed 1.
  bool clamp = true;
};

// The map lit from `light_dir`: a direction toward the light in the light frame (x right, y
// up the image, z toward the camera), normalised here. For a flat sample under an overhead
// camera (lu, lv) is its (x, y). A light at or below the horizon (z <= 0) gives a black image
// (the model has no light from behind). Throws ptmkit::Error for a non-finite or zero vector.
// Output: 3 channels (RGB), normalised units, in the map's colour space. Rows are computed in
// parallel; every pixel depends only on its texel, so the result is the same for any number
// of threads.
// Any basis: PTM maps by CoefficientMap::evaluate, HSH maps (.rti, texture/rti.h) by the basis
// at the light summed per channel.
[[nodiscard]] Image relight(const CoefficientMap& map, const Eigen::Vector3d& light_dir,
                            const RelightOptions& options = {});

// `light_dir` normalised; throws ptmkit::Error if it is non-finite or zero.
[[nodiscard]] Eigen::Vector3d normalised_light(const Eigen::Vector3d& light_dir);

// Relighting at every light of a set (typically a test .lp), with comparison to the photos.
struct RelightSetOptions {
  // Folder for the relit images (created if missing). Each image takes the file name (not the
  // folder) of its light's image; two lights with the same file name are an error.
  std::filesystem::path out_dir;
  RelightOptions relight;
  // Sample type of the written images (the type of file comes from each name's extension).
  ImageWriteOptions write;
  // Optional mask image (one channel, map size): only pixels > 0.5 are compared.
  std::filesystem::path mask;
  // Optional JSON report (written atomically, last).
  std::filesystem::path report_json;
};

struct RelightSetEntry {
  std::filesystem::path output;     // the relit image written
  std::filesystem::path reference;  // the light's photo, as named in the set
  Eigen::Vector3d light_dir{0, 0, 1};
  bool compared = false;  // false when the photo does not exist
  ImageComparison comparison;
};

struct RelightSetReport {
  std::vector<RelightSetEntry> entries;
  std::size_t compared = 0;
  // Means over the compared lights (mean of the per-light values; a PSNR of +inf, an
  // identical image, makes the mean +inf). NaN when nothing was compared.
  double mean_psnr_db = 0.0;
  double mean_abs_grey = 0.0;
  std::filesystem::path report_json;
  [[nodiscard]] std::string brief() const;
  // The report as JSON text (infinite and NaN values become null).
  [[nodiscard]] std::string to_json() const;
};

// Relights at every light of `lights`, writes the images into options.out_dir, compares each
// with its photo where the photo exists, and writes the JSON report if asked. Everything is
// checked first (photo sizes, mask, name clashes); if anything fails midway, the images this
// call had written (and the folder, if it created it) are removed before the Error propagates.
RelightSetReport relight_light_set(const CoefficientMap& map, const LightSet& lights,
                                   const RelightSetOptions& options);

}  // namespace ptmkit::texture
