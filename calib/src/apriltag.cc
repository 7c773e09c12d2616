#include "ptmkit/calib/apriltag.h"

#include <algorithm>
#include <cmath>
#include <memory>

#include <apriltag/apriltag.h>
#include <apriltag/tag16h5.h>
#include <apriltag/tag25h9.h>
#include <apriltag/tag36h11.h>
#include <apriltag/tagCircle21h7.h>
#include <apriltag/tagCircle49h12.h>
#include <apriltag/tagCustom48h12.h>
#include <apriltag/tagStandard41h12.h>
#include <apriltag/tagStandard52h13.h>

#include "ptmkit/core/colour.h"
#include "ptmkit/core/error.h"

namespace ptmkit::calib {

namespace {

struct FamilyInfo {
  TagFamily family;
  const char* name;
  apriltag_family_t* (*create)();
  void (*destroy)(apriltag_family_t*);
};

const FamilyInfo kFamilies[] = {
    {TagFamily::k36h11, "tag36h11", tag36h11_create, tag36h11_destroy},
    {TagFamily::k25h9, "tag25h9", tag25h9_create, tag25h9_destroy},
    {TagFamily::k16h5, "tag16h5", tag16h5_create, tag16h5_destroy},
    {TagFamily::kCircle21h7, "tagCircle21h7", tagCircle21h7_create, tagCircle21h7_destroy},
    {TagFamily::kCircle49h12, "tagCircle49h12", tagCircle49h12_create, tagCircle49h12_destroy},
    {TagFamily::kStandard41h12, "tagStandard41h12", tagStandard41h12_create,
     tagStandard41h12_destroy},
    {TagFamily::kStandard52h13, "tagStandard52h13", tagStandard52h13_create,
     tagStandard52h13_destroy},
    {TagFamily::kCustom48h12, "tagCustom48h12", tagCustom48h12_create, tagCustom48h12_destroy},
};

const FamilyInfo& info(TagFamily family) {
  for (const auto& f : kFamilies) {
    if (f.family == family) return f;
  }
  return kFamilies[0];
}

std::string lower(std::string_view s) {
  std::string out(s);
  std::transform(out.begin(), out.end(), out.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return out;
}

}  // namespace

TagFamily parse_tag_family(std::string_view name) {
  const std::string want = lower(name);
  for (const auto& f : kFamilies) {
    const std::string full = lower(f.name);
    if (want == full || "tag" + want == full) return f.family;
  }
  std::string known;
  for (const auto& f : kFamilies) known += std::string(known.empty() ? "" : ", ") + f.name;
  throw Error("unknown AprilTag family '" + std::string(name) + "' (known: " + known + ")");
}

std::string_view to_string(TagFamily family) { return info(family).name; }

std::string TagDetectorOptions::validate() const {
  if (!(quad_decimate >= 1.0 && quad_decimate <= 8.0)) return "quad_decimate must be in [1, 8]";
  if (!(quad_sigma >= 0.0 && quad_sigma <= 10.0)) return "quad_sigma must be in [0, 10]";
  if (max_hamming < 0 || max_hamming > 3) return "max_hamming must be 0..3";
  if (threads < 1) return "threads must be at least 1";
  if (!(min_decision_margin >= 0.0)) return "min_decision_margin must be >= 0";
  return {};
}

std::vector<TagDetection> detect_tags(ConstImageViewF image, const TagDetectorOptions& options) {
  if (const auto err = options.validate(); !err.empty()) throw Error("tag detector: " + err);
  if (image.empty()) throw Error("tag detector: empty image");
  if (image.channels != 1 && image.channels != 3 && image.channels != 4) {
    throw Error("tag detector: expected a grey, RGB or RGBA image, got " +
                std::to_string(image.channels) + " channels");
  }
  // The library wants 8-bit grey with its own row stride (it may be padded).
  std::unique_ptr<image_u8_t, void (*)(image_u8_t*)> grey(
      image_u8_create(static_cast<unsigned>(image.width), static_cast<unsigned>(image.height)),
      image_u8_destroy);
  for (int y = 0; y < image.height; ++y) {
    const float* row = image.row(y);
    std::uint8_t* out = grey->buf + static_cast<std::ptrdiff_t>(y) * grey->stride;
    for (int x = 0; x < image.width; ++x) {
      const float* p = row + static_cast<std::ptrdiff_t>(x) * image.channels;
      const double v = image.channels == 1 ? p[0] : luma(p[0], p[1], p[2]);
      out[x] = static_cast<std::uint8_t>(std::lround(std::clamp(v, 0.0, 1.0) * 255.0));
    }
  }

  const FamilyInfo& fam = info(options.family);
  std::unique_ptr<apriltag_family_t, void (*)(apriltag_family_t*)> family(fam.create(),
                                                                          fam.destroy);
  std::unique_ptr<apriltag_detector_t, void (*)(apriltag_detector_t*)> detector(
      apriltag_detector_create(), apriltag_detector_destroy);
  apriltag_detector_add_family_bits(detector.get(), family.get(), options.max_hamming);
  detector->quad_decimate = static_cast<float>(options.quad_decimate);
  detector->quad_sigma = static_cast<float>(options.quad_sigma);
  detector->refine_edges = options.refine_edges;
  detector->nthreads = options.threads;

  zarray_t* raw = apriltag_detector_detect(detector.get(), grey.get());
  std::vector<TagDetection> out;
  for (int i = 0; i < zarray_size(raw); ++i) {
    apriltag_detection_t* d = nullptr;
    zarray_get(raw, i, &d);
    if (d->decision_margin < options.min_decision_margin) continue;
    TagDetection t;
    t.id = d->id;
    t.hamming = d->hamming;
    t.decision_margin = d->decision_margin;
    // The library puts pixel centres at (0.5, 0.5) (its origin is the top-left pixel's outer
    // corner); ours is the centre of that pixel, as OpenCV's.
    t.centre_px = {d->c[0] - 0.5, d->c[1] - 0.5};
    for (int k = 0; k < 4; ++k) {
      t.corners_px[static_cast<std::size_t>(k)] = {d->p[k][0] - 0.5, d->p[k][1] - 0.5};
    }
    out.push_back(t);
  }
  apriltag_detections_destroy(raw);
  std::sort(out.begin(), out.end(), [](const TagDetection& a, const TagDetection& b) {
    if (a.id != b.id) return a.id < b.id;
    if (a.centre_px.y() != b.centre_px.y()) return a.centre_px.y() < b.centre_px.y();
    return a.centre_px.x() < b.centre_px.x();
  });
  return out;
}

}  // namespace ptmkit::calib
