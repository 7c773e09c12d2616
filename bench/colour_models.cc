// Accuracy and storage of the three colour models on a capture with held-out lights: fits the
// training lights with each model, writes the .ptm, relights at the test lights and compares
// with the test photographs. Usage: colour_models TRAIN.lp TEST.lp [MASK.png]
// Prints a Markdown table (the one in docs/FITTING.md).
#include <cstdio>
#include <filesystem>
#include <optional>

#include "ptmkit/core/error.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/core/light_set.h"
#include "ptmkit/fit/fit.h"
#include "ptmkit/texture/metrics.h"
#include "ptmkit/texture/ptm.h"
#include "ptmkit/texture/relight.h"

namespace fs = std::filesystem;

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: colour_models TRAIN.lp TEST.lp [MASK.png]\n");
    return 2;
  }
  try {
    const ptmkit::LightSet train = ptmkit::read_lp(argv[1]);
    const ptmkit::LightSet test = ptmkit::read_lp(argv[2]);
    std::optional<ptmkit::Image> mask;
    if (argc > 3) mask = ptmkit::read_image(argv[3]);
    std::vector<ptmkit::Image> photos;
    for (const auto& l : test.lights) photos.push_back(ptmkit::read_image(l.image));
    const fs::path tmp = fs::temp_directory_path() / "ptmkit-colour-models.ptm";
    std::printf(
        "| model | held-out PSNR (dB) | mean abs (grey) | fit residual rms (grey) | file "
        "bytes/texel |\n");
    std::printf("|---|---|---|---|---|\n");
    for (auto model :
         {ptmkit::ColourModel::kRGB, ptmkit::ColourModel::kLRGB, ptmkit::ColourModel::kYCC}) {
      ptmkit::fit::FitOptions options;
      options.model = model;
      ptmkit::texture::PtmStreamWriter writer(tmp);
      const auto report = ptmkit::fit::fit_capture(train, options, writer);
      const auto map = ptmkit::texture::read_ptm(tmp, report.colour_space);
      double psnr = 0.0, mae = 0.0;
      for (std::size_t i = 0; i < test.size(); ++i) {
        const auto relit = ptmkit::texture::relight(map, test.lights[i].direction);
        ptmkit::ConstImageViewF mask_view;
        if (mask) mask_view = mask->view();
        const auto cmp = ptmkit::texture::compare_images(relit.view(), photos[i].view(),
                                                         mask ? &mask_view : nullptr);
        psnr += cmp.psnr_db;
        mae += cmp.mean_abs_grey;
      }
      const auto info = ptmkit::texture::read_ptm_info(tmp);
      std::printf("| %s | %.2f | %.2f | %.2f | %d |\n",
                  std::string(ptmkit::to_string(model)).c_str(),
                  psnr / static_cast<double>(test.size()), mae / static_cast<double>(test.size()),
                  report.residuals.rms_grey, info.bytes_per_texel());
    }
    fs::remove(tmp);
  } catch (const ptmkit::Error& e) {
    std::fprintf(stderr, "colour_models: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
