// The parsed .ptm header, shared by the reader (ptm_read.cc) and write_ptm_file's check of a
// header kept from reading (ptm_write.cc); parsed in ptm_header.cc.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>

#include "ptm_internal.h"
#include "ptmkit/texture/ptm.h"

namespace ptmkit::texture::internal {

struct Header {
  PtmVersion version = PtmVersion::k1_2;
  PtmFormat format = PtmFormat::kRGB;
  PtmCompression compression = PtmCompression::kNone;
  // PTM_FORMAT_LUM: format is kLRGB, and the file holds the luminance block only.
  bool luminance_only = false;
  int width = 0;
  int height = 0;
  PtmQuantisation quantisation;
  internal::JpegPtmHeader jpeg;
  std::size_t header_bytes = 0;

  [[nodiscard]] std::size_t texels() const {
    return static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  }
};

// Parses the text header at `data` (`size` bytes); errors name `path` and the line.
Header parse_header(const std::uint8_t* data, std::size_t size, const std::filesystem::path& path);

}  // namespace ptmkit::texture::internal
