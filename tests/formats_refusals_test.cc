// The one wording of every refusal: each .ptm, .rti and web-folder variant that is not read
// names itself and says what is supported (texture/formats.h).
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "formats_test_util.h"
#include "ptmkit/core/error.h"
#include "ptmkit/texture/formats.h"
#include "ptmkit/texture/texture_file.h"
#include "test_util.h"

namespace fs = std::filesystem;

namespace ptmkit::texture {
namespace {

using test::ScratchDir;
using test::write_text;

TEST(Refusals, EveryUnsupportedVariantSaysWhatIsSupported) {
  ScratchDir dir;
  const std::string tail = "\n1\n1\n1 1 1 1 1 1\n0 0 0 0 0 0\n" + std::string(64, '\0');
  struct Case {
    std::string file;
    std::string content;
    std::string variant;
  };
  std::vector<Case> cases;
  for (const char* f : {"PTM_FORMAT_PTM_LUT", "PTM_FORMAT_PTM_C_LUT", "PTM_FORMAT_JPEGLS_RGB",
                        "PTM_FORMAT_JPEGLS_LRGB", "PTM_FORMAT_PAL_RGB"}) {
    cases.push_back({std::string(f) + ".ptm", "PTM_1.2\n" + std::string(f) + tail,
                     "format " + std::string(f) + " is not supported"});
  }
  cases.push_back({"old.ptm", "PTM_1.1\nPTM_FORMAT_JPEG_LRGB" + tail,
                   "PTM_1.1 PTM_FORMAT_JPEG_LRGB is not supported"});
  cases.push_back({"type2.rti", "#HSH1.2\r\n2\r\n1 1 3\r\n9 2 1\r\n", "RTI type 2 is not"});
  for (const Case& c : cases) {
    write_text(dir / c.file, c.content);
    try {
      (void)read_texture(dir / c.file);
      ADD_FAILURE() << c.file << " was accepted";
    } catch (const Error& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find(c.variant), std::string::npos) << msg;
      EXPECT_NE(msg.find(std::string(kSupportedFormats)), std::string::npos) << msg;
    }
  }
  // Web folders of types, colour spaces and layouts not read.
  struct WebCase {
    std::string type, colorspace, file, variant;
  };
  const std::vector<WebCase> web = {
      {"rbf", "mrgb", "plane_0.jpg", "web folder type 'rbf'"},
      {"bilinear", "mrgb", "plane_0.jpg", "web folder type 'bilinear'"},
      {"sh", "rgb", "plane_0.jpg", "web folder type 'sh'"},
      {"ptm", "mrgb", "plane_0.jpg", "colour space 'mrgb' with type 'ptm'"},
      {"ptm", "mycc", "plane_0.jpg", "colour space 'mycc' with type 'ptm'"},
      {"hsh", "lrgb", "plane_0.jpg", "colour space 'lrgb' with type 'hsh'"},
      {"ptm", "rgb", "plane_0.tzi", "layout tarzoom"},
  };
  int n = 0;
  for (const WebCase& c : web) {
    const fs::path folder = dir / ("web" + std::to_string(n++));
    fs::create_directories(folder);
    nlohmann::json j = {{"width", 4},
                        {"height", 4},
                        {"format", "jpg"},
                        {"type", c.type},
                        {"colorspace", c.colorspace},
                        {"nplanes", 18}};
    j["materials"] = {
        {{"scale", std::vector<double>(18, 1.0)}, {"bias", std::vector<double>(18, 0.0)}}};
    write_text(folder / "info.json", j.dump());
    write_text(folder / c.file, "x");
    for (const fs::path& p : {folder, folder / "info.json"}) {
      try {
        (void)read_texture(p);
        ADD_FAILURE() << c.variant << " was accepted";
      } catch (const Error& e) {
        const std::string msg = e.what();
        EXPECT_NE(msg.find(c.variant + " is not supported"), std::string::npos) << msg;
        EXPECT_NE(msg.find(std::string(kSupportedFormats)), std::string::npos) << msg;
      }
    }
  }
}

}  // namespace
}  // namespace ptmkit::texture
