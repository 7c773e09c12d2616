// Reading and writing polynomial texture maps in HP's .ptm format (version 1.2; 1.1 LRGB is
// read too).
//
// File layout (PTM 1.2, uncompressed):
//   PTM_1.2                     magic
//   PTM_FORMAT_RGB              or PTM_FORMAT_LRGB
//   W                           width, on its own line
//   H                           height, on its own line (some viewers need the separate lines)
//   s0 s1 s2 s3 s4 s5           float scales, one per coefficient index
//   b0 b1 b2 b3 b4 b5           integer biases in 0..255
//   <binary block>
// A stored byte k of coefficient index i means a_i = s_i * (k - b_i), with the polynomial
// giving 0..255 units. Rows are stored bottom-up: the first stored row is the image's bottom
// row. PTM_FORMAT_RGB stores three planes R, G, B, each W*H*6 bytes (a0..a5 per pixel).
// PTM_FORMAT_LRGB (1.2) stores a W*H*6 block of luminance coefficients, then a W*H*3 block
// of RGB bytes; the output is clamp(L / 255 * rgb). PTM 1.1 LRGB interleaves the 9 bytes of
// each pixel (a0..a5, r, g, b).
//
// Mapping to CoefficientMap (normalised units, 1.0 at full scale): a file coefficient is
// 255 times a map coefficient.
//   kRGB  -> PTM_FORMAT_RGB.
//   kLRGB -> PTM_FORMAT_LRGB, rgb byte = round(255 * colour) clamped to 0..255 (the map keeps
//            the colour's largest channel at 1, so the bytes use the full range).
//   kYCC  -> PTM_FORMAT_RGB, exactly: the three polynomials share a0..a4 (the Y polynomial)
//            and differ only in a5: R = Y + 1.402 Cr, G = Y - 0.344136 Cb - 0.714136 Cr,
//            B = Y + 1.772 Cb (core/colour.h from_ycbcr applied to (a5, cb, cr)).
// Reading gives kRGB or kLRGB; see decode_ptm.
//
// JPEG-compressed files (PTM_FORMAT_JPEG_RGB, PTM_FORMAT_JPEG_LRGB, PTM 1.2) are read into the
// same uncompressed layout (PtmFile::data), so everything downstream treats them alike. After
// the biases their header holds, for N = 18 (RGB) or 9 (LRGB) component planes: the
// compression parameter (JPEG quality), N transforms, N horizontal and N vertical motion
// vectors, N decode-order ranks, N reference planes (-1: none), N JPEG stream sizes and N
// side-information sizes. Then, per plane in plane order, its greyscale JPEG stream and its side
// information. Planes 0..5 are a0..a5 (of R, then G, then B for RGB), LRGB's planes 6..8 its
// R, G, B bytes; JPEG rows are stored rows (bottom-up). Planes are decoded in rank order; a
// plane with a reference holds a difference: value = stored + ref - 128 (ref replaced by
// 255 - ref when its transform has bit 0, plane inversion), negative sums wrapped by +256 as
// RTIViewer and the other public readers do, sums above 255 clamped. Side information is
// 5-byte records (big-endian 32-bit position in the JPEG's raster order, then the byte) that
// overwrite single samples after the difference. Motion compensation (transform bit 1, or a
// non-zero motion vector) is refused: no known writer used it and no public reader applies it.
//
// Biases are read as any integer: some encoders write negative ones (a constant-term bias of
// -7) and every common reader accepts them; a byte still decodes to scale * (byte - bias).
//
// Quantisation rule (choose_quantisation): per coefficient index i, shared by every texel and
// every plane, over the file coefficients' actual range [lo_i, hi_i] widened to include 0.
// The bias is an integer, so the byte equal to the bias decodes to exactly 0: a coefficient
// that is 0 in the map (a flat texel's a0..a4, say) stays exactly 0, and a constant map
// relights to a constant. The bias is the byte nearest -lo / (hi - lo) * 255 (of its floor
// and ceiling, the one giving the smaller scale) and the scale the smallest that reaches both
// ends from it; bytes are round(a / s + b) clamped to 0..255. The worst-case coefficient
// error is half a step, s_i / 2 (file units). An all-zero index gets scale 1, bias 0.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "ptmkit/core/coefficients.h"
#include "ptmkit/core/collective.h"

namespace ptmkit::texture {

enum class PtmVersion { k1_1, k1_2 };
enum class PtmFormat { kRGB, kLRGB };
// How the binary block is stored: raw bytes, or one JPEG stream per component plane.
enum class PtmCompression { kNone, kJpeg };
[[nodiscard]] std::string_view to_string(PtmVersion version);  // "PTM_1.1", "PTM_1.2"
[[nodiscard]] std::string_view to_string(PtmFormat format);    // "PTM_FORMAT_RGB", ...
// The format line of a file: "PTM_FORMAT_JPEG_LRGB" for (kLRGB, kJpeg), ...
[[nodiscard]] std::string_view format_name(PtmFormat format, PtmCompression compression);

// The six scales and biases of a file, shared by every texel and every plane.
struct PtmQuantisation {
  std::array<float, kPtmTerms> scales{1, 1, 1, 1, 1, 1};
  std::array<int, kPtmTerms> biases{0, 0, 0, 0, 0, 0};
  bool operator==(const PtmQuantisation&) const = default;
};

// Quantisation for file coefficients (0..255 units) spanning [lo[i], hi[i]] per index i, by
// the rule above. Non-finite bounds are a programmer error.
// With `integer_scales`, every scale is a whole number (the smallest that, with an integer
// bias, reaches both ends): (byte - bias) * scale is then an integer, so a reader that
// truncates it to an integer (RTIViewer does) loses nothing; the price is a coarser step for
// coefficients whose range is under 255 units (docs/FORMATS.md has the measured trade).
[[nodiscard]] PtmQuantisation choose_quantisation(const std::array<double, kPtmTerms>& lo,
                                                  const std::array<double, kPtmTerms>& hi,
                                                  bool integer_scales = false);

// Header fields of a file.
struct PtmInfo {
  std::filesystem::path path;
  PtmVersion version = PtmVersion::k1_2;
  PtmFormat format = PtmFormat::kRGB;
  // PTM_FORMAT_LUM (format is then kLRGB): one luminance polynomial a texel, no colour.
  bool luminance_only = false;
  int width = 0;
  int height = 0;
  PtmQuantisation quantisation;
  PtmCompression compression = PtmCompression::kNone;
  int compression_parameter = 0;   // JPEG files: the quality their header declares
  std::size_t header_bytes = 0;    // text header, including its last line end
  std::size_t data_bytes = 0;      // binary block the header implies (JPEG: streams + side info)
  std::size_t file_bytes = 0;      // size on disk
  std::size_t trailing_bytes = 0;  // bytes after the binary block (read_ptm_file refuses them)

  // Bytes per texel in the file: 18 for RGB, 9 for LRGB, 6 for LUM.
  [[nodiscard]] int bytes_per_texel() const;
  // The format line as the file spells it (PTM_FORMAT_LUM included).
  [[nodiscard]] std::string_view format_line() const;
};

// A .ptm file in memory, as stored: enough to write it back bit-exactly.
struct PtmFile {
  PtmVersion version = PtmVersion::k1_2;
  PtmFormat format = PtmFormat::kRGB;
  // Read from a PTM_FORMAT_LUM file: format is kLRGB and data holds a white colour block
  // after the luminance block, so every LRGB path evaluates it (grey = the polynomial).
  // Written back as PTM_FORMAT_LRGB.
  bool luminance_only = false;
  int width = 0;
  int height = 0;
  PtmQuantisation quantisation;
  // How the file was (or is to be) stored. data is always the uncompressed layout; a kJpeg
  // file is written with one JPEG stream per plane at `compression_parameter` quality (1..100;
  // order 0..N-1, no references, no side information), so a rewrite is not bit-exact.
  PtmCompression compression = PtmCompression::kNone;
  int compression_parameter = 0;
  // The binary block in file order (bottom-up rows; planar for 1.2, interleaved for 1.1).
  std::vector<std::uint8_t> data;
  // Bytes written after the binary block. Always empty from read_ptm_file (which refuses a file
  // with bytes after its block); write_ptm_file writes them after the block.
  std::vector<std::uint8_t> trailing;
  // The header text exactly as read (including its last line end). write_ptm_file writes it
  // verbatim when it still says what the fields above say (so foreign spacing, CRLF and
  // number spellings survive a rewrite); otherwise, and when empty, the canonical header:
  // one item per line, scales in the shortest form that reads back to the same float.
  std::string header;

  [[nodiscard]] std::size_t texels() const { return static_cast<std::size_t>(width) * height; }
  // Stored byte of coefficient `term` of `plane` (0..2 for RGB, 0 for LRGB) at (x, y), y
  // counted from the top as in CoefficientMap.
  [[nodiscard]] std::uint8_t coeff_byte(int x, int y, int plane, int term) const;
  // Stored colour byte (0 = r .. 2 = b) of an LRGB file at (x, y), y from the top.
  [[nodiscard]] std::uint8_t rgb_byte(int x, int y, int channel) const;
  // Decoded coefficient in file units (0..255): scale * (byte - bias).
  [[nodiscard]] double coefficient(int x, int y, int plane, int term) const;
  // The canonical header text for the fields above.
  [[nodiscard]] std::string canonical_header() const;
};

// Reads a whole file. Accepted: any whitespace between header items (spaces, tabs, line
// breaks, CRLF; scales or biases split across lines), trailing spaces on the last header
// line. Errors (ptmkit::Error naming the
// file and the problem): a missing or unreadable file, a wrong magic, an unsupported version
// or format (compressed and palette formats, PTM 1.1 RGB), a non-numeric, non-positive or
// absurd width or height (each at most kMaxPtmSide, W*H at most kMaxPtmTexels), a NaN,
// infinite or zero scale, a bias that is not an integer, a header whose last line is not
// terminated, a binary block shorter or longer than the header implies (expected and present
// byte counts given: bytes after the block mean the header does not describe the data, e.g. a
// duplicated header line), a path that is not a regular file, a file larger than the memory
// available, and for JPEG files a stream that does not decode to a W x H greyscale image, side
// information that is not whole 5-byte records inside the image, decode ranks that are not a
// permutation, a reference to a plane not decoded before, and motion compensation. Unsupported
// variants (PTM_FORMAT_LUM, PTM_FORMAT_PTM_LUT, PTM_FORMAT_PTM_C_LUT, PTM_FORMAT_JPEGLS_*, ...)
// are refused with texture/formats.h's wording. Negative scales are accepted: the format allows
// them.
[[nodiscard]] PtmFile read_ptm_file(const std::filesystem::path& path);
// The header only (the binary block's presence is not checked; file_bytes says how much is
// there).
[[nodiscard]] PtmInfo read_ptm_info(const std::filesystem::path& path);
// Writes a file atomically, exactly as held (see PtmFile::header). Returns the bytes written
// (a JPEG variant's compressed size, which PtmFile::data does not tell).
std::size_t write_ptm_file(const std::filesystem::path& path, const PtmFile& file);

inline constexpr int kMaxPtmSide = 1 << 20;
// Biases read and written: any integer of at most this magnitude.
inline constexpr int kMaxPtmBias = 1 << 20;
inline constexpr std::size_t kMaxPtmTexels = std::size_t{1} << 32;

struct PtmWriteOptions {
  // Relit quantisation error is measured at these light directions (light frame, z > 0).
  // Empty: the seed paper's once-subdivided geodesic dome (40 lights, core/light_layout.h).
  std::vector<Eigen::Vector3d> report_lights;
  // At most this many texels (a fixed stride over the map) enter the relit error, so the
  // report costs little at any size: 65536 texels x 40 lights x 3 channels is 7.9 million
  // samples, plenty for the mean and PSNR (the max is the max over them). At 2^18 it cost a
  // third of a least-squares fit of a 320 x 320 capture. 0 skips the relit error.
  std::size_t report_max_texels = std::size_t{1} << 16;
  // PtmStreamWriter only: at most this many bytes of its half-float coefficients stay in
  // memory (whole rows, from the top); the rows beyond go to an unnamed temporary file in the
  // output's folder (a 12-megapixel kRGB fit: 432 MB of coefficients, 365 MB of them spilled,
  // read back once by end()). The page cache still serves them when memory is free; the
  // process's own footprint stays bounded. Spilling only the excess rather than everything
  // saved 0.4 s of a 2.4 s fit; 64 MiB rather than 192 MiB took a 12-megapixel fit's peak
  // from 226 to 153 MiB (LRGB) and 255 to 127 MiB (RGB) at the same speed within the
  // machine's noise (docs/PERFORMANCE.md). 0: always in memory.
  std::size_t spill_above_bytes = std::size_t{64} << 20;
  // Whole-number scales (see choose_quantisation), for readers that truncate
  // (byte - bias) * scale to an integer. Off: the finest scales (the bytes fit has always
  // written).
  bool integer_scales = false;
  // PtmStreamWriter only, a fit shared by several processes (core/collective.h): this process
  // writes image rows [row_offset, row_offset + begin()'s layout height) of a file
  // `full_height` rows tall, and the others the rest. The processes agree on the
  // quantisation (the coefficients' range over all of them) before any byte is written; rank
  // 0 creates the temporary file, every process writes its rows into it, and rank 0 renames
  // it after every process succeeded. The bytes are those one process would write. The relit
  // error is not measured (relit_samples 0). nullptr: one process.
  Collective* collective = nullptr;
  int row_offset = 0;
  int full_height = 0;
};

// What quantisation cost.
struct PtmWriteReport {
  std::filesystem::path path;
  PtmFormat format = PtmFormat::kRGB;
  PtmQuantisation quantisation;
  std::size_t file_bytes = 0;
  // Coefficient error over every stored coefficient (normalised units, map scale; for kYCC
  // the written RGB polynomials, for kLRGB the luminance polynomial).
  double max_coeff_error = 0.0;
  double rms_coeff_error = 0.0;
  // Relit error, quantised vs unquantised, clamped to [0, 1], in grey levels (1/255 of full
  // scale), over report_lights and the sampled texels, all three channels.
  double relit_mean_abs_grey = 0.0;
  double relit_max_abs_grey = 0.0;
  double relit_psnr_db = 0.0;  // peak 1.0 in normalised units; +inf when identical
  std::size_t relit_samples = 0;
  [[nodiscard]] std::string brief() const;
};

// Quantises a map into a file in memory (no I/O). `report` (optional) gets the errors.
[[nodiscard]] PtmFile encode_ptm(const CoefficientMap& map, const PtmWriteOptions& options = {},
                                 PtmWriteReport* report = nullptr);
// encode_ptm + write_ptm_file.
PtmWriteReport write_ptm(const std::filesystem::path& path, const CoefficientMap& map,
                         const PtmWriteOptions& options = {});

// The file's polynomials as a map in normalised units. PTM_FORMAT_RGB gives kRGB with
// coefficient = scale * (byte - bias) / 255. PTM_FORMAT_LRGB gives kLRGB keeping the map's
// convention that the colour's largest channel is 1: with m the texel's largest rgb byte,
// colour = rgb / m and the luminance coefficients are multiplied by m / 255, so the product
// (what is seen) is the file's exactly; a black texel (m = 0) keeps colour 0. The format has
// no colour space: the caller says what the fitted values were.
[[nodiscard]] CoefficientMap decode_ptm(const PtmFile& file,
                                        ColourSpace colour_space = ColourSpace::kSRGB);
// read_ptm_file + decode_ptm.
[[nodiscard]] CoefficientMap read_ptm(const std::filesystem::path& path,
                                      ColourSpace colour_space = ColourSpace::kSRGB);

// A file's contents summarised (what `ptmkit info` shows).
struct PtmSummary {
  PtmInfo info;
  // Per coefficient index: the range the stored bytes actually take, and the range the scale
  // and bias can represent, both in file units (0..255).
  std::array<double, kPtmTerms> coeff_min{}, coeff_max{};
  std::array<double, kPtmTerms> representable_min{}, representable_max{};
  // Memory per texel: in the file, and as a float CoefficientMap once decoded.
  int file_bytes_per_texel = 0;
  int map_bytes_per_texel = 0;
};
// Reads the whole file (so a truncated file is reported) and summarises it.
[[nodiscard]] PtmSummary summarise_ptm(const std::filesystem::path& path);

// Streams a fit into a .ptm without a float copy of the map. Per texel it keeps the file's
// polynomials (normalised units) as IEEE half floats — 2 bytes per coefficient instead of 4:
// 36 bytes per texel for kRGB, 16 for kYCC (a0..a4 shared, three a5), 12 for kLRGB plus 3
// colour bytes — and their running min/max. end() chooses the quantisation, encodes, and
// writes the file atomically. The result equals write_ptm on the same map except where
// rounding a coefficient to half (relative error at most 2^-11) moves it across a byte
// boundary: each byte then differs by one step, so a relit value differs by at most
// sum_i scale_i * |basis_i| / 255 and in practice by less than one grey level (tested).
// The report compares the written file with the half values. The file is encoded and written
// in slices of rows, so end() needs no buffer of the file's size; beyond
// PtmWriteOptions::spill_above_bytes the half floats themselves live in a temporary file.
class PtmStreamWriter final : public CoefficientSink {
 public:
  explicit PtmStreamWriter(std::filesystem::path path, PtmWriteOptions options = {});
  ~PtmStreamWriter() override;
  PtmStreamWriter(const PtmStreamWriter&) = delete;
  PtmStreamWriter& operator=(const PtmStreamWriter&) = delete;

  // Throws ptmkit::Error for a basis other than PTM or a size the format cannot hold.
  void begin(const CoefficientLayout& layout) override;
  // Bands must arrive top to bottom, consecutive; anything else throws std::logic_error.
  void write_rows(int y0, int rows, const float* coeffs, const float* colour) override;
  // Throws std::logic_error if rows are missing, ptmkit::Error if the write fails.
  void end() override;

  // Valid after end().
  [[nodiscard]] const PtmWriteReport& report() const { return report_; }
  // Bytes of half-float coefficients and colour bytes held until end(), in memory or (see
  // spilled()) in the temporary file.
  [[nodiscard]] std::size_t buffer_bytes() const;
  // Whether begin() put some of the coefficients in a temporary file (see spill_above_bytes).
  [[nodiscard]] bool spilled() const;

  struct Impl;  // storage, defined in the implementation

 private:
  std::filesystem::path path_;
  PtmWriteOptions options_;
  PtmWriteReport report_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace ptmkit::texture
