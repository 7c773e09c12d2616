// PTM_FORMAT_JPEG_RGB / PTM_FORMAT_JPEG_LRGB planes (layout and rules: ptm.h).
#include <algorithm>
#include <string>
#include <vector>

#include "jpeg_codec.h"
#include "ptm_internal.h"
#include "ptmkit/core/error.h"

namespace fs = std::filesystem;

namespace ptmkit::texture::internal {

namespace {

// Offset in the uncompressed PTM 1.2 layout of plane `k`'s sample at stored pixel `pixel`.
std::size_t raw_offset(PtmFormat format, std::size_t texels, int k, std::size_t pixel) {
  if (format == PtmFormat::kRGB) {
    const auto colour = static_cast<std::size_t>(k / kPtmTerms);
    const auto term = static_cast<std::size_t>(k % kPtmTerms);
    return colour * texels * kPtmTerms + pixel * kPtmTerms + term;
  }
  if (k < kPtmTerms) return pixel * kPtmTerms + static_cast<std::size_t>(k);
  return texels * kPtmTerms + pixel * 3 + static_cast<std::size_t>(k - kPtmTerms);
}

}  // namespace

std::vector<std::uint8_t> decode_jpeg_planes(const std::uint8_t* data, std::size_t size,
                                             const JpegPtmHeader& header, PtmFormat format,
                                             int width, int height, const fs::path& path) {
  const int n = jpeg_planes(format);
  const std::size_t texels = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  const std::string name(format_name(format, PtmCompression::kJpeg));
  for (int k = 0; k < n; ++k) {
    if ((header.transforms[k] & 2) != 0 || header.motion_x[k] != 0 || header.motion_y[k] != 0) {
      throw Error(where(path) + ": " + name + " plane " + std::to_string(k) +
                  " uses motion compensation, which is not supported (no public reader "
                  "applies it)");
    }
    if (header.side_bytes[k] % 5 != 0) {
      throw Error(where(path) + ": side information of plane " + std::to_string(k) + " has " +
                  std::to_string(header.side_bytes[k]) + " bytes, not whole 5-byte records");
    }
  }
  // Decode ranks must be a permutation of 0..n-1.
  std::vector<int> by_rank(static_cast<std::size_t>(n), -1);
  for (int k = 0; k < n; ++k) {
    int& slot = by_rank[static_cast<std::size_t>(header.order[k])];
    if (slot >= 0) {
      throw Error(where(path) + ": planes " + std::to_string(slot) + " and " + std::to_string(k) +
                  " have the same decode order " + std::to_string(header.order[k]));
    }
    slot = k;
  }
  // Every stream decoded as stored (JPEG raster = stored rows, bottom-up).
  std::vector<std::vector<std::uint8_t>> planes(static_cast<std::size_t>(n));
  std::vector<std::size_t> side_at(static_cast<std::size_t>(n));
  std::size_t pos = 0;
  for (int k = 0; k < n; ++k) {
    const std::size_t bytes = header.stream_bytes[k];
    if (bytes > size - pos) {
      throw Error(where(path) + ": JPEG stream of plane " + std::to_string(k) + " runs past " +
                  "the end of the file");
    }
    int w = 0, h = 0;
    std::string why;
    if (!jpeg_decode(data + pos, bytes, 1, width, height, &planes[k], &w, &h, &why)) {
      throw Error(where(path) + ": " + name + " plane " + std::to_string(k) + " (" +
                  std::to_string(bytes) + " bytes at offset " + std::to_string(pos) +
                  " of the binary block) does not decode: " + why +
                  " (wrong stream size in the header, or a truncated file?)");
    }
    pos += bytes;
    side_at[k] = pos;
    pos += header.side_bytes[k];
  }
  // Differences, in decode order.
  std::vector<bool> done(static_cast<std::size_t>(n), false);
  for (int rank = 0; rank < n; ++rank) {
    const int k = by_rank[static_cast<std::size_t>(rank)];
    std::vector<std::uint8_t>& plane = planes[k];
    const int r = header.reference[k];
    if (r >= 0) {
      if (r == k || !done[static_cast<std::size_t>(r)]) {
        throw Error(where(path) + ": plane " + std::to_string(k) + " is stored as a difference " +
                    "from plane " + std::to_string(r) + ", which is not decoded before it");
      }
      const bool invert = (header.transforms[k] & 1) != 0;
      const std::vector<std::uint8_t>& ref = planes[r];
      for (std::size_t i = 0; i < texels; ++i) {
        const int base = invert ? 255 - ref[i] : ref[i];
        int v = plane[i] + base - 128;
        if (v < 0) v += 256;  // as the public readers wrap
        plane[i] = static_cast<std::uint8_t>(std::min(v, 255));
      }
    }
    const std::uint8_t* side = data + side_at[k];
    for (std::size_t s = 0; s < header.side_bytes[k]; s += 5) {
      const std::size_t at = (std::size_t{side[s]} << 24) | (std::size_t{side[s + 1]} << 16) |
                             (std::size_t{side[s + 2]} << 8) | std::size_t{side[s + 3]};
      if (at >= texels) {
        throw Error(where(path) + ": side information of plane " + std::to_string(k) +
                    " names sample " + std::to_string(at) + ", outside the " +
                    std::to_string(texels) + "-sample image");
      }
      plane[at] = side[s + 4];
    }
    done[static_cast<std::size_t>(k)] = true;
  }
  std::vector<std::uint8_t> raw(texels * static_cast<std::size_t>(bytes_per_texel(format)));
  for (int k = 0; k < n; ++k) {
    const std::vector<std::uint8_t>& plane = planes[k];
    for (std::size_t i = 0; i < texels; ++i) raw[raw_offset(format, texels, k, i)] = plane[i];
  }
  return raw;
}

void encode_jpeg_planes(const PtmFile& file, int quality, std::string* header_tail,
                        std::vector<std::uint8_t>* block) {
  const int n = jpeg_planes(file.format);
  const std::size_t texels = file.texels();
  std::vector<std::uint8_t> plane(texels);
  std::vector<std::size_t> sizes(static_cast<std::size_t>(n));
  block->clear();
  for (int k = 0; k < n; ++k) {
    for (std::size_t i = 0; i < texels; ++i) {
      plane[i] = file.data[raw_offset(file.format, texels, k, i)];
    }
    std::vector<std::uint8_t> stream;
    std::string why;
    if (!jpeg_encode_grey(plane.data(), file.width, file.height, quality, &stream, &why)) {
      throw Error("cannot encode JPEG plane " + std::to_string(k) + ": " + why);
    }
    sizes[static_cast<std::size_t>(k)] = stream.size();
    block->insert(block->end(), stream.begin(), stream.end());
  }
  auto line = [&](auto value_of) {
    for (int k = 0; k < n; ++k) {
      *header_tail += std::to_string(value_of(k));
      *header_tail += k + 1 < n ? ' ' : '\n';
    }
  };
  *header_tail = std::to_string(quality) + '\n';
  line([](int) { return 0; });    // transforms
  line([](int) { return 0; });    // motion vectors x
  line([](int) { return 0; });    // motion vectors y
  line([](int k) { return k; });  // decode order
  line([](int) { return -1; });   // reference planes
  line([&](int k) { return sizes[static_cast<std::size_t>(k)]; });
  line([](int) { return 0; });  // side information
}

}  // namespace ptmkit::texture::internal
