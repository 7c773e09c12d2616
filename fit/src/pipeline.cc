// The fit pipeline: band source -> row fitter -> sink, three bands in flight; the light model
// (distant or near), the design, and the public entry points fit_capture and fit_images.
#include <algorithm>
#include <chrono>
#include <functional>
#include <limits>
#include <optional>

#include <tbb/task_arena.h>
#include <tbb/task_group.h>

#include "ptmkit/core/error.h"
#include "ptmkit/core/stack_reader.h"
#include "ptmkit/fit/fit.h"
#include "residual_stats.h"
#include "row_fitter.h"

namespace ptmkit::fit {

namespace {

using internal::FitSetup;
using internal::NearFit;
using internal::RowFitter;
using internal::RowStats;
using internal::StatsTotal;

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

using BandSource = std::function<bool(int rows, StackBand* band)>;

// Sizes the optional maps a fit fills.
void prepare_outputs(FitOutputs* o, int width, int height, int lights) {
  if (o == nullptr) return;
  const auto px = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  o->residual_map = o->want_residual_map ? Image(width, height, 1, ColourSpace::kLinear) : Image();
  o->outlier_counts =
      o->want_outlier_counts ? Image(width, height, 2, ColourSpace::kLinear) : Image();
  o->labels.assign(o->want_labels ? px * static_cast<std::size_t>(lights) : 0, 0);
  o->normals = o->want_normals ? Image(width, height, 3, ColourSpace::kLinear) : Image();
  o->albedo = o->want_normals ? Image(width, height, 3, ColourSpace::kLinear) : Image();
}

// Runs the bands of `next_band` through `fitter` into `sink` (begin and write_rows; the caller
// ends it). Fills the report's timings, residuals and outlier counts.
void run_pipeline(const FitSetup& setup, const RowFitter& fitter, const BandSource& next_band,
                  CoefficientSink& sink, FitReport* report_out) {
  const FitOptions& options = *setup.options;
  const int height = setup.height;
  FitReport& report = *report_out;
  StatsTotal totals;
  // Three bands in flight: band k is fitted while band k + 1 is decoded and band k - 1 is
  // handed to the sink, so neither the decoding nor the sink (the .ptm writer converts and
  // checks every coefficient) waits for the other on a machine with few cores.
  struct Fitted {
    int y0 = 0, rows = 0;
    std::vector<float> coeffs, colour;
    std::vector<RowStats> row_stats;
  };
  StackBand bands[2];
  Fitted fitted[2];
  sink.begin(setup.layout);

  auto td = Clock::now();
  bool have = next_band(options.band_rows, &bands[0]);
  report.decode_seconds += seconds_since(td);
  int cur = 0;
  const Fitted* pending = nullptr;  // fitted, not yet given to the sink
  const auto deliver = [&](const Fitted& f) {
    sink.write_rows(f.y0, f.rows, f.coeffs.data(), f.colour.data());
  };
  while (have) {
    bool have_next = false;
    double decode_s = 0.0;
    tbb::task_group group;
    group.run([&] {
      const auto t = Clock::now();
      have_next = next_band(options.band_rows, &bands[1 - cur]);
      decode_s = seconds_since(t);
    });
    if (pending) group.run([&deliver, pending] { deliver(*pending); });
    Fitted& out = fitted[cur];
    const auto tf = Clock::now();
    try {
      out.y0 = bands[cur].y0;
      out.rows = bands[cur].rows;
      fitter.fit(bands[cur], &out.coeffs, &out.colour, &out.row_stats);
    } catch (...) {
      group.wait();
      throw;
    }
    report.fit_seconds += seconds_since(tf);
    group.wait();  // rethrows a decode or sink error
    report.decode_seconds += decode_s;
    // Merged in band order: the totals are the same whatever the threads.
    for (const auto& rs : out.row_stats) {
      if (rs.active) totals.merge(rs);
      totals.merge_outliers(rs);
    }
    if (pending && options.progress) {
      options.progress(static_cast<double>(pending->y0 + pending->rows) / height);
    }
    pending = &out;
    cur = 1 - cur;
    have = have_next;
  }
  if (pending) {
    deliver(*pending);
    if (options.progress) options.progress(1.0);
  }
  // The caller ends the sink once the images are closed and the bands freed: the sink may
  // need memory of its own to finish (the .ptm writer encodes the whole file then).
  report.residuals = totals.finish();
  report.residuals.row_step = internal::residual_row_step(setup.width, height);
  report.outliers = totals.outliers;
  report.light_model.singular_texels = totals.singular_texels;
}

// The design options a solver implies: QR/SVD factorisations, ridge's default weight.
DesignOptions design_options_for(const FitOptions& options) {
  DesignOptions d = options.design;
  if (options.solver == Solver::kQR) d.method = PinvMethod::kQR;
  if (options.solver == Solver::kSVD) d.method = PinvMethod::kSVD;
  if (options.solver == Solver::kRidge && d.ridge_lambda == 0.0) d.ridge_lambda = 1e-3;
  return d;
}

// Ends the sink and counts its time (writing the file) in the total.
void finish_sink(CoefficientSink& sink, FitReport* report) {
  const auto t = Clock::now();
  sink.end();
  report->total_seconds += seconds_since(t);
}

// The light model of a fit: near (per-texel directions) when a sample plane is given, else
// distant. Checks what can be checked before any image is read.
struct LightModelSetup {
  std::optional<NearLightModel> model;
  NearLightReport report;
  NearFit fit(const FitOptions& options) const {
    NearFit f;
    if (!model) return f;
    f.model = &*model;
    f.falloff = options.near.falloff;
    f.ridge_lambda = design_options_for(options).ridge_lambda;
    return f;
  }
  // The images' size must be the plane's.
  void check_size(int width, int height) const {
    if (!model) return;
    const SamplePlane& p = model->plane();
    if (p.width_px != width || p.height_px != height) {
      throw Error("fit: the sample plane is for " + std::to_string(p.width_px) + "x" +
                  std::to_string(p.height_px) + " images but the capture is " +
                  std::to_string(width) + "x" + std::to_string(height));
    }
  }
  void finish(FitReport* out) const {
    NearLightReport r = report;
    r.singular_texels = out->light_model.singular_texels;
    out->light_model = r;
  }
};

LightModelSetup light_model_setup(const LightSet& lights, const FitOptions& options) {
  LightModelSetup setup;
  if (!options.near.plane) {
    const bool positions = std::any_of(lights.lights.begin(), lights.lights.end(),
                                       [](const Light& l) { return l.position_mm.has_value(); });
    if (positions) setup.report.note = "light positions ignored: no sample plane given";
    return setup;
  }
  if (options.solver != Solver::kLS && options.solver != Solver::kRidge) {
    throw Error(
        "fit: near lights (a sample plane was given) are supported by the ls and ridge "
        "solvers only, not '" +
        std::string(to_string(options.solver)) +
        "' (its per-texel labelling uses the shared distant-light design); fit near "
        "lights with --solver ls or ridge, or drop the plane for the distant model");
  }
  setup.model = NearLightModel::from_lights(lights, *options.near.plane);
  setup.report = setup.model->field_report();
  setup.report.falloff_corrected = options.near.falloff;
  return setup;
}

// Where a fit's bands come from: files (StackReader) or images in memory, one channel rule.
struct OpenedSource {
  int width = 0;
  int height = 0;
  int channels = 0;
  ColourSpace colour_space = ColourSpace::kSRGB;
  // Photo pixel of the first texel (a crop or mask box); the light model's plane maps photo
  // pixels, of a photo full_width x full_height.
  int origin_x = 0;
  int origin_y = 0;
  int full_width = 0;
  int full_height = 0;
  // Float files are not clipped at full scale (HDR): no sample is "saturated".
  bool unclipped = false;
  // One quantisation step of the samples (normalised): 1/255 for 8-bit files and images in
  // memory, 1/65535 for 16-bit and float files. The robust scale's floor is counted in it.
  double grey_step = 1.0 / 255.0;
  BandSource next;
};

// The design a fit's basis needs, built (and its layout checked) before any image is read.
struct Designs {
  std::optional<LightDesign> ptm;
  std::optional<BasisDesign> basis;
  DesignReport report;
};

Designs build_designs(const std::vector<Eigen::Vector3d>& dirs, const FitOptions& options) {
  Designs d;
  if (options.basis == Basis::kPtm) {
    d.ptm = LightDesign::build(dirs, design_options_for(options));
    d.report = d.ptm->report();
  } else {
    d.basis = BasisDesign::build(options.basis, dirs, design_options_for(options));
    d.report.lights = static_cast<int>(dirs.size());
    d.report.condition_number = d.basis->condition_number;
    d.report.regularised = design_options_for(options).ridge_lambda > 0.0;
  }
  return d;
}

// Fits a source's bands into the sink (begin and rows; the caller ends it).
FitReport fit_source(const Designs& designs, const LightModelSetup& light_model,
                     const FitOptions& options, const OpenedSource& source, CoefficientSink& sink,
                     FitOutputs* outputs) {
  const auto t0 = Clock::now();
  light_model.check_size(source.full_width, source.full_height);
  FitOptions run_options = options;
  if (source.unclipped) {
    run_options.robust.saturation_level = std::numeric_limits<double>::infinity();
  }
  // RobustOptions::min_scale is in grey levels of 8-bit input: a 16-bit capture's noise floor
  // is 257 times finer, and a floor of 8-bit steps would hide its outliers (dark captures most).
  run_options.robust.min_scale *= source.grey_step * 255.0;
  const bool ptm = options.basis == Basis::kPtm;
  FitSetup setup;
  setup.options = &run_options;
  setup.width = source.width;
  setup.height = source.height;
  setup.channels = source.channels;
  setup.colour_space = source.colour_space;
  setup.near = light_model.fit(run_options);
  setup.near.origin_x = source.origin_x;
  setup.near.origin_y = source.origin_y;
  // Other bases deliver luminance fits multiplied out (core/coefficients.h).
  setup.layout = {source.width, source.height, options.basis,
                  ptm ? options.model : ColourModel::kRGB, source.colour_space};
  const bool wants =
      outputs != nullptr && (outputs->want_residual_map || outputs->want_outlier_counts ||
                             outputs->want_labels || outputs->want_normals);
  setup.outputs = wants ? outputs : nullptr;
  prepare_outputs(outputs, source.width, source.height, designs.report.lights);

  FitReport report;
  report.lights = designs.report.lights;
  report.width = source.width;
  report.height = source.height;
  report.channels = source.channels;
  report.basis = options.basis;
  report.model = ptm || source.channels == 3 ? options.model : ColourModel::kLRGB;
  report.colour_space = source.colour_space;
  report.design = designs.report;
  report.solver = options.solver;
  report.robust = run_options.robust;
  report.threads = options.threads > 0 ? options.threads : tbb::this_task_arena::max_concurrency();
  const auto fitter = internal::make_row_fitter(setup, designs.ptm ? &*designs.ptm : nullptr,
                                                designs.basis ? &*designs.basis : nullptr);
  run_pipeline(setup, *fitter, source.next, sink, &report);
  light_model.finish(&report);
  report.total_seconds = seconds_since(t0);
  return report;
}

FitReport fit_in_memory(const std::vector<Image>& images,
                        const std::vector<Eigen::Vector3d>& light_dirs, const FitOptions& options,
                        CoefficientSink& sink, FitOutputs* outputs,
                        const LightModelSetup& light_model) {
  if (images.size() != light_dirs.size()) {
    throw Error("fit: " + std::to_string(images.size()) + " images but " +
                std::to_string(light_dirs.size()) + " light directions");
  }
  if (images.empty()) throw Error("fit: no images");
  const ThreadLimit limit(options.threads);
  const Designs designs = build_designs(light_dirs, options);
  for (std::size_t i = 0; i < images.size(); ++i) {
    if (images[i].width() != images[0].width() || images[i].height() != images[0].height() ||
        images[i].channels() != images[0].channels()) {
      throw Error("fit: image " + std::to_string(i) + " differs in size or channels from image 0");
    }
  }
  OpenedSource source;
  source.width = images[0].width();
  source.height = images[0].height();
  source.channels = sample_channels(images[0].channels());
  source.colour_space = images[0].colour_space();
  source.full_width = source.width;
  source.full_height = source.height;
  int next_row = 0;
  source.next = [&](int rows, StackBand* band) {
    try {
      if (!read_image_band(images, next_row, rows, band)) return false;
    } catch (const Error& e) {
      throw Error(std::string("fit: ") + e.what());
    }
    next_row += band->rows;
    return true;
  };
  FitReport report = fit_source(designs, light_model, options, source, sink, outputs);
  finish_sink(sink, &report);
  return report;
}

LightSet lights_from_directions(const std::vector<Eigen::Vector3d>& dirs) {
  LightSet lights;
  for (const auto& d : dirs) {
    Light l;
    l.direction = d;
    lights.lights.push_back(l);
  }
  return lights;
}

}  // namespace

FitReport fit_capture(const LightSet& lights, const FitOptions& options, CoefficientSink& sink,
                      FitOutputs* outputs) {
  if (const auto err = options.validate(); !err.empty()) throw Error("fit options: " + err);
  const ThreadLimit limit(options.threads);
  // Check the layout before opening a single image: a bad layout fails fast.
  const Designs designs = build_designs(lights.directions(), options);
  const LightModelSetup light_model = light_model_setup(lights, options);
  FitReport report;
  {
    StackReader reader(lights.images(), options.input);
    OpenedSource source;
    source.width = reader.width();
    source.height = reader.height();
    source.origin_x = reader.origin_x();
    source.origin_y = reader.origin_y();
    source.full_width = reader.summary().full_width;
    source.full_height = reader.summary().full_height;
    source.channels = reader.channels();
    source.colour_space = reader.info().colour_space;
    source.unclipped = reader.info().format == PixelFormat::kF32;
    source.grey_step = reader.info().format == PixelFormat::kU8 ? 1.0 / 255.0 : 1.0 / 65535.0;
    source.next = [&](int rows, StackBand* band) {
      return reader.read_band(rows, band, BandStorage::kNative8);
    };
    report = fit_source(designs, light_model, options, source, sink, outputs);
    report.input = reader.summary();
  }  // images closed before the sink finishes
  finish_sink(sink, &report);
  return report;
}

FitReport fit_images(const std::vector<Image>& images,
                     const std::vector<Eigen::Vector3d>& light_dirs, const FitOptions& options,
                     CoefficientSink& sink, FitOutputs* outputs) {
  if (const auto err = options.validate(); !err.empty()) throw Error("fit options: " + err);
  return fit_in_memory(images, light_dirs, options, sink, outputs,
                       light_model_setup(lights_from_directions(light_dirs), options));
}

FitReport fit_images(const std::vector<Image>& images, const LightSet& lights,
                     const FitOptions& options, CoefficientSink& sink, FitOutputs* outputs) {
  if (const auto err = options.validate(); !err.empty()) throw Error("fit options: " + err);
  return fit_in_memory(images, lights.directions(), options, sink, outputs,
                       light_model_setup(lights, options));
}

}  // namespace ptmkit::fit
