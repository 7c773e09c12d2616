#include "ptmkit/texture/web_folder.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <iterator>
#include <regex>
#include <system_error>

#include <nlohmann/json.hpp>

#include "jpeg_codec.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/json_file.h"
#include "ptmkit/texture/formats.h"
#include "ptmkit/texture/ptm.h"

namespace fs = std::filesystem;

namespace ptmkit::texture {

namespace {

fs::path folder_of(const fs::path& path) {
  std::error_code ec;
  if (fs::is_directory(path, ec)) return path;
  return path.parent_path().empty() ? fs::path(".") : path.parent_path();
}

std::vector<std::uint8_t> read_all(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(where(path) + ": cannot open for reading");
  std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(in)),
                                  std::istreambuf_iterator<char>());
  if (in.bad()) throw Error(where(path) + ": read failed");
  return bytes;
}

// An attribute of the first element named `element` in a small XML text (a .dzi).
bool xml_int(const std::string& xml, const std::string& element, const std::string& attribute,
             int* value) {
  const std::size_t at = xml.find("<" + element);
  if (at == std::string::npos) return false;
  const std::size_t end = xml.find('>', at);
  const std::string tag = xml.substr(at, end == std::string::npos ? std::string::npos : end - at);
  const std::regex re(attribute + "\\s*=\\s*\"\\s*([0-9]+)\\s*\"");
  std::smatch m;
  if (!std::regex_search(tag, m, re)) return false;
  const long long v = std::stoll(m[1].str());
  if (v > (1LL << 30)) return false;
  *value = static_cast<int>(v);
  return true;
}

std::string xml_string(const std::string& xml, const std::string& element,
                       const std::string& attribute) {
  const std::size_t at = xml.find("<" + element);
  if (at == std::string::npos) return {};
  const std::size_t end = xml.find('>', at);
  const std::string tag = xml.substr(at, end == std::string::npos ? std::string::npos : end - at);
  const std::regex re(attribute + "\\s*=\\s*\"([^\"]*)\"");
  std::smatch m;
  return std::regex_search(tag, m, re) ? m[1].str() : std::string();
}

std::string plane_name(int j) { return "plane_" + std::to_string(j); }

// One decoded JPEG of the folder: w x h x 3 bytes, rows top to bottom.
std::vector<std::uint8_t> decode_file(const fs::path& file, int expect_w, int expect_h) {
  std::error_code ec;
  if (!fs::is_regular_file(file, ec)) throw Error(where(file) + ": missing");
  const std::vector<std::uint8_t> bytes = read_all(file);
  std::vector<std::uint8_t> pixels;
  int w = 0, h = 0;
  std::string why;
  if (!internal::jpeg_decode(bytes.data(), bytes.size(), 3, expect_w, expect_h, &pixels, &w, &h,
                             &why)) {
    throw Error(where(file) + ": " + why);
  }
  return pixels;
}

std::vector<std::uint8_t> read_plane_image(const WebFolderInfo& info, int j) {
  if (info.layout == "image") {
    return decode_file(info.folder / (plane_name(j) + ".jpg"), info.width, info.height);
  }
  // deepzoom: the highest level folder is the full resolution.
  const fs::path files = info.folder / (plane_name(j) + "_files");
  int top = -1;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(files, ec)) {
    const std::string n = entry.path().filename().string();
    if (entry.is_directory() && !n.empty() && n.size() < 4 &&
        std::all_of(n.begin(), n.end(), [](char c) { return c >= '0' && c <= '9'; })) {
      top = std::max(top, std::stoi(n));
    }
  }
  if (ec || top < 0) throw Error(where(files) + ": no tile levels found");
  const int ts = info.tile_size, ov = info.overlap;
  const int cols = (info.width + ts - 1) / ts, rows = (info.height + ts - 1) / ts;
  std::vector<std::uint8_t> image(static_cast<std::size_t>(info.width) * info.height * 3);
  const fs::path level = files / std::to_string(top);
  tbb::parallel_for(0, rows * cols, [&](int t) {
    const int tx = t % cols, ty = t / cols;
    const int x0 = tx * ts, y0 = ty * ts;
    const int cw = std::min(ts, info.width - x0), ch = std::min(ts, info.height - y0);
    const int left = tx > 0 ? ov : 0, top_ov = ty > 0 ? ov : 0;
    const int tw = cw + left + (tx + 1 < cols ? std::min(ov, info.width - x0 - cw) : 0);
    const int th = ch + top_ov + (ty + 1 < rows ? std::min(ov, info.height - y0 - ch) : 0);
    const fs::path tile = level / (std::to_string(tx) + "_" + std::to_string(ty) + ".jpg");
    const std::vector<std::uint8_t> px = decode_file(tile, tw, th);
    for (int y = 0; y < ch; ++y) {
      std::copy_n(px.data() + (static_cast<std::size_t>(y + top_ov) * tw + left) * 3,
                  static_cast<std::size_t>(cw) * 3,
                  image.data() + (static_cast<std::size_t>(y0 + y) * info.width + x0) * 3);
    }
  });
  return image;
}

}  // namespace

bool is_web_folder(const fs::path& path) {
  std::error_code ec;
  if (fs::is_directory(path, ec)) return fs::is_regular_file(path / "info.json", ec);
  return path.filename() == "info.json";
}

WebFolderInfo read_web_info(const fs::path& path) {
  WebFolderInfo info;
  info.folder = folder_of(path);
  const fs::path json_path = info.folder / "info.json";
  std::error_code ec;
  if (!fs::is_regular_file(json_path, ec)) throw Error(where(json_path) + ": no such file");
  if (fs::file_size(json_path, ec) > (std::uintmax_t{64} << 20)) {
    throw Error(where(json_path) + ": too large for an info.json");
  }
  nlohmann::json j;
  try {
    const std::vector<std::uint8_t> bytes = read_all(json_path);
    j = nlohmann::json::parse(bytes.begin(), bytes.end());
  } catch (const nlohmann::json::exception& e) {
    throw Error(where(json_path) + ": not valid JSON: " + e.what());
  }
  const std::string at = where(json_path) + ": ";
  auto integer = [&](const char* key, bool required, int fallback) {
    if (!j.contains(key)) {
      if (required) throw Error(at + "no '" + key + "'");
      return fallback;
    }
    return json_int(j, key, 1, kMaxPtmSide, where(json_path));
  };
  auto text = [&](const char* key, const char* fallback) {
    if (!j.contains(key)) {
      if (fallback == nullptr) throw Error(at + "no '" + key + "'");
      return std::string(fallback);
    }
    if (!j[key].is_string()) throw Error(at + "'" + key + "' is not a string");
    return j[key].get<std::string>();
  };
  if (!j.is_object()) throw Error(at + "not a JSON object");
  info.width = integer("width", true, 0);
  info.height = integer("height", true, 0);
  if (static_cast<std::size_t>(info.width) * static_cast<std::size_t>(info.height) >
      kMaxPtmTexels) {
    throw Error(at + "size " + std::to_string(info.width) + " x " + std::to_string(info.height) +
                " is absurd");
  }
  info.type = text("type", nullptr);
  if (info.type != "ptm" && info.type != "hsh") {
    throw Error(at + unsupported_variant("web folder type '" + info.type + "'"));
  }
  info.colorspace = text("colorspace", "rgb");
  if (info.colorspace != "rgb" && !(info.type == "ptm" && info.colorspace == "lrgb")) {
    throw Error(at + unsupported_variant("web folder colour space '" + info.colorspace +
                                         "' with type '" + info.type + "'"));
  }
  const std::string format = text("format", "jpg");
  if (format != "jpg" && format != "jpeg") {
    throw Error(at + unsupported_variant("web folder plane format '" + format + "'"));
  }
  info.nplanes = integer("nplanes", false, 0);
  int expected = 0;
  if (info.type == "ptm") {
    expected = info.colorspace == "rgb" ? 18 : 9;
  } else {
    expected = info.nplanes;
    if (expected != 12 && expected != 27 && expected != 48) {
      throw Error(at + "an hsh folder has 12, 27 or 48 planes (4, 9 or 16 terms), 'nplanes' " +
                  "says " + std::to_string(info.nplanes));
    }
  }
  if (info.nplanes == 0) info.nplanes = expected;
  if (info.nplanes != expected) {
    throw Error(at + "a " + info.type + " " + info.colorspace + " folder has " +
                std::to_string(expected) + " planes, 'nplanes' says " +
                std::to_string(info.nplanes));
  }
  if (j.contains("quality") && j["quality"].is_number_integer() &&
      j["quality"].get<long long>() >= 0 && j["quality"].get<long long>() <= 100) {
    info.quality = j["quality"].get<int>();
  }
  if (j.contains("pixelSizeInMM") && j["pixelSizeInMM"].is_number()) {
    info.pixel_size_mm = j["pixelSizeInMM"].get<double>();
  }
  if (j.contains("lights") && j["lights"].is_array() && j["lights"].size() % 3 == 0) {
    const auto& l = j["lights"];
    for (std::size_t i = 0; i + 2 < l.size(); i += 3) {
      if (!l[i].is_number() || !l[i + 1].is_number() || !l[i + 2].is_number()) break;
      info.lights.emplace_back(l[i].get<double>(), l[i + 1].get<double>(), l[i + 2].get<double>());
    }
  }
  if (!j.contains("materials") || !j["materials"].is_array() || j["materials"].empty() ||
      !j["materials"][0].is_object()) {
    throw Error(at + "no 'materials' (the planes' scale and bias)");
  }
  if (j["materials"].size() > 1) {
    throw Error(at + unsupported_variant("a web folder with " +
                                         std::to_string(j["materials"].size()) + " materials"));
  }
  const auto& m = j["materials"][0];
  auto values = [&](const char* key, std::vector<double>* out) {
    if (!m.contains(key) || !m[key].is_array() ||
        m[key].size() != static_cast<std::size_t>(info.nplanes)) {
      throw Error(at + "materials[0]." + key + " must list " + std::to_string(info.nplanes) +
                  " numbers, one per plane");
    }
    for (const auto& v : m[key]) {
      if (!v.is_number() || !std::isfinite(v.get<double>())) {
        throw Error(at + "materials[0]." + key + " holds a value that is not a finite number");
      }
      out->push_back(v.get<double>());
    }
  };
  values("scale", &info.scale);
  values("bias", &info.bias);
  // Layout, from the files present.
  if (fs::is_regular_file(info.folder / (plane_name(0) + ".jpg"), ec)) {
    info.layout = "image";
  } else if (fs::is_regular_file(info.folder / (plane_name(0) + ".dzi"), ec)) {
    info.layout = "deepzoom";
    const fs::path dzi = info.folder / (plane_name(0) + ".dzi");
    const std::vector<std::uint8_t> bytes = read_all(dzi);
    const std::string xml(bytes.begin(), bytes.end());
    int w = 0, h = 0;
    if (!xml_int(xml, "Image", "TileSize", &info.tile_size) || info.tile_size <= 0 ||
        !xml_int(xml, "Image", "Overlap", &info.overlap) || !xml_int(xml, "Size", "Width", &w) ||
        !xml_int(xml, "Size", "Height", &h)) {
      throw Error(where(dzi) +
                  ": not a deep-zoom descriptor (TileSize, Overlap, Size Width and "
                  "Height expected)");
    }
    if (w != info.width || h != info.height) {
      throw Error(where(dzi) + ": " + std::to_string(w) + " x " + std::to_string(h) +
                  ", but info.json says " + std::to_string(info.width) + " x " +
                  std::to_string(info.height));
    }
    const std::string tile_format = xml_string(xml, "Image", "Format");
    if (tile_format != "jpg" && tile_format != "jpeg") {
      throw Error(where(dzi) + ": " +
                  unsupported_variant("deep-zoom tile format '" + tile_format + "'"));
    }
  } else {
    for (const char* other : {".tzi", ".tzb"}) {
      if (fs::exists(info.folder / (plane_name(0) + other), ec)) {
        throw Error(where(info.folder) + ": " + unsupported_variant("web folder layout tarzoom"));
      }
    }
    throw Error(where(info.folder) + ": " +
                unsupported_variant("a web folder with neither plane_0.jpg nor plane_0.dzi"));
  }
  return info;
}

WebTexture read_web_folder(const fs::path& path, ColourSpace colour_space) {
  WebTexture out;
  out.info = read_web_info(path);
  const WebFolderInfo& info = out.info;
  const std::size_t texels = static_cast<std::size_t>(info.width) * info.height;
  std::vector<std::vector<std::uint8_t>> jpegs(static_cast<std::size_t>(info.jpegs()));
  for (int j = 0; j < info.jpegs(); ++j) jpegs[j] = read_plane_image(info, j);
  // Coefficient of plane k at texel i.
  auto coef = [&](int k, std::size_t i) {
    const double b =
        jpegs[static_cast<std::size_t>(k / 3)][i * 3 + static_cast<std::size_t>(k % 3)];
    return (b / 255.0 - info.bias[static_cast<std::size_t>(k)]) *
           info.scale[static_cast<std::size_t>(k)];
  };
  if (info.type == "hsh") {
    out.is_hsh = true;
    const int terms = info.nplanes / 3;
    out.hsh = CoefficientMap(
        {info.width, info.height, hsh_basis_of_terms(terms), ColourModel::kRGB, colour_space});
    tbb::parallel_for(std::size_t{0}, texels, [&](std::size_t i) {
      float* t = out.hsh.coeffs.data() + i * 3 * static_cast<std::size_t>(terms);
      for (int c = 0; c < 3; ++c) {
        for (int k = 0; k < terms; ++k) t[c * terms + k] = static_cast<float>(coef(3 * k + c, i));
      }
    });
    return out;
  }
  // Web term order 1, u, v, u^2, uv, v^2 -> .ptm order u^2, v^2, uv, u, v, 1.
  static constexpr int kWebTerm[kPtmTerms] = {3, 5, 4, 1, 2, 0};
  if (info.colorspace == "rgb") {
    out.ptm = CoefficientMap(info.width, info.height, ColourModel::kRGB, colour_space);
    tbb::parallel_for(std::size_t{0}, texels, [&](std::size_t i) {
      float* a = out.ptm.coeffs.data() + i * 3 * kPtmTerms;
      for (int c = 0; c < 3; ++c) {
        for (int t = 0; t < kPtmTerms; ++t) {
          a[c * kPtmTerms + t] = static_cast<float>(coef(3 * kWebTerm[t] + c, i));
        }
      }
    });
    return out;
  }
  out.ptm = CoefficientMap(info.width, info.height, ColourModel::kLRGB, colour_space);
  tbb::parallel_for(std::size_t{0}, texels, [&](std::size_t i) {
    float* a = out.ptm.coeffs.data() + i * kPtmTerms;
    float* col = out.ptm.colour.data() + i * 3;
    double rgb[3];
    for (int c = 0; c < 3; ++c) rgb[c] = coef(c, i);
    // The map keeps the colour's largest channel at 1 (core/coefficients.h): the luminance
    // takes the factor, so colour * luminance is the folder's value.
    const double m = std::max({rgb[0], rgb[1], rgb[2]});
    for (int c = 0; c < 3; ++c) col[c] = m > 0.0 ? static_cast<float>(rgb[c] / m) : 0.0f;
    const double factor = m > 0.0 ? m : 0.0;
    for (int t = 0; t < kPtmTerms; ++t) {
      a[t] = static_cast<float>(coef(3 + kWebTerm[t], i) * factor);
    }
  });
  return out;
}

}  // namespace ptmkit::texture
