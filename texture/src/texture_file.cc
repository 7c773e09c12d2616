#include "ptmkit/texture/texture_file.h"

#include "ptmkit/texture/ptm.h"
#include "ptmkit/texture/web_folder.h"

namespace fs = std::filesystem;

namespace ptmkit::texture {

TextureSource detect_texture_source(const fs::path& path) {
  if (is_web_folder(path)) return TextureSource::kWebFolder;
  if (path.extension() == ".rti") return TextureSource::kRti;
  if (path.extension() == ".ptm") return TextureSource::kPtm;
  return looks_like_rti(path) ? TextureSource::kRti : TextureSource::kPtm;
}

LoadedTexture read_texture(const fs::path& path, ColourSpace colour_space) {
  LoadedTexture t;
  t.source = detect_texture_source(path);
  switch (t.source) {
    case TextureSource::kWebFolder: {
      WebTexture w = read_web_folder(path, colour_space);
      t.is_hsh = w.is_hsh;
      t.ptm = std::move(w.ptm);
      t.hsh = std::move(w.hsh);
      t.format = "web folder " + w.info.type + " " + w.info.colorspace + " " + w.info.layout;
      break;
    }
    case TextureSource::kRti:
      t.is_hsh = true;
      t.hsh = read_rti(path, colour_space);
      t.format = "RTI HSH " + std::to_string(t.hsh.terms()) + " terms";
      break;
    case TextureSource::kPtm: {
      const PtmFile file = read_ptm_file(path);
      t.format = file.luminance_only ? "PTM_FORMAT_LUM"
                                     : std::string(format_name(file.format, file.compression));
      t.ptm = decode_ptm(file, colour_space);
      break;
    }
  }
  return t;
}

}  // namespace ptmkit::texture
