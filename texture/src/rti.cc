#include "ptmkit/texture/rti.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>

#include "ptmkit/core/atomic_file.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/limits.h"
#include "ptmkit/core/raw_file.h"
#include "ptmkit/texture/formats.h"

namespace fs = std::filesystem;

namespace ptmkit::texture {

namespace {

constexpr long long kMaxSide = 1 << 20;
constexpr long long kMaxTexels = 1LL << 32;

static_assert(std::endian::native == std::endian::little, "the .rti floats are little-endian");

}  // namespace

int hsh_terms(int order) {
  if (order < 2 || order > 4) {
    throw Error("HSH order must be 2, 3 or 4 (4, 9 or 16 terms), got " + std::to_string(order));
  }
  return order * order;
}

int hsh_order(int terms) {
  switch (terms) {
    case 4:
      return 2;
    case 9:
      return 3;
    case 16:
      return 4;
    default:
      return 0;
  }
}

Basis hsh_basis_of_terms(int terms) {
  switch (terms) {
    case 4:
      return Basis::kHsh2;
    case 9:
      return Basis::kHsh3;
    case 16:
      return Basis::kHsh4;
    default:
      throw Error("an HSH basis has 4, 9 or 16 terms, not " + std::to_string(terms));
  }
}

namespace {

// write_rti for one process or a share of several (RtiWriter's RtiShare).
RtiWriteReport write_rti_rows(const fs::path& path, const CoefficientMap& map,
                              const RtiShare& share) {
  Collective* const peers = share.collective;
  const int t = map.terms();
  if (map.basis == Basis::kPtm || hsh_order(t) == 0) {
    throw Error(where(path) + ": an .rti holds an HSH basis (4, 9 or 16 terms), the map is " +
                std::string(to_string(map.basis)));
  }
  if (map.model != ColourModel::kRGB) {
    throw Error(where(path) + ": an .rti holds three channels of coefficients, the map is " +
                std::string(to_string(map.model)));
  }
  if (map.width <= 0 || map.height <= 0 || map.coeffs.size() != map.texels() * 3 * t) {
    throw Error(where(path) + ": the map's size does not match its coefficients");
  }
  const int full_height = peers != nullptr ? share.full_height : map.height;
  const int row_offset = peers != nullptr ? share.row_offset : 0;
  // Every process checks its rows; they agree before anything is written.
  try {
    check_coefficients(path, map.coeffs.data(), map.coeffs.size(), map.width, 3 * t, row_offset);
  } catch (const Error&) {
    if (peers != nullptr) (void)peers->all(false);
    throw;
  }
  if (peers != nullptr) peers->agree(true, where(path));
  // Per term: the range over every texel and channel (of every process).
  std::vector<double> lo(t, std::numeric_limits<double>::infinity());
  std::vector<double> hi(t, -std::numeric_limits<double>::infinity());
  for (std::size_t i = 0; i < map.coeffs.size(); ++i) {
    const auto v = static_cast<double>(map.coeffs[i]);
    const auto k = static_cast<std::size_t>(i % static_cast<std::size_t>(t));
    lo[k] = std::min(lo[k], v);
    hi[k] = std::max(hi[k], v);
  }
  if (peers != nullptr) {
    peers->min(lo.data(), lo.size());
    peers->max(hi.data(), hi.size());
  }
  std::vector<float> scale(t), bias(t);
  for (int k = 0; k < t; ++k) {
    // The ranges are of floats: back to float exactly.
    const auto l = static_cast<float>(lo[k]);
    const auto h = static_cast<float>(hi[k]);
    bias[k] = l;
    // A constant term still needs a non-zero scale (readers divide by it).
    scale[k] = h > l ? h - l : 1e-6f;
  }
  std::ostringstream header;
  // CRLF, as CHI's HSH fitter writes: a widely used Java viewer counts header bytes assuming
  // two-byte line ends.
  header << "#HSH1.2\r\n3\r\n" << map.width << ' ' << full_height << " 3\r\n" << t << " 2 1\r\n";
  std::string head = header.str();
  const std::size_t data0 = head.size() + 2 * sizeof(float) * t;
  head.resize(data0);
  std::memcpy(head.data() + data0 - 2 * sizeof(float) * t, scale.data(), sizeof(float) * t);
  std::memcpy(head.data() + data0 - sizeof(float) * t, bias.data(), sizeof(float) * t);
  std::vector<unsigned char> bytes(map.coeffs.size());
  RtiWriteReport report;
  report.path = path;
  double sum_sq = 0.0;
  for (std::size_t i = 0; i < map.coeffs.size(); ++i) {
    const auto k = static_cast<int>(i % static_cast<std::size_t>(t));
    const double q = (map.coeffs[i] - bias[k]) / scale[k] * 255.0;
    const auto b = static_cast<unsigned char>(std::clamp(std::lround(q), 0L, 255L));
    bytes[i] = b;
    const double back = b / 255.0 * scale[k] + bias[k];
    const double e = std::abs(back - map.coeffs[i]);
    report.max_coeff_error = std::max(report.max_coeff_error, e);
    sum_sq += e * e;
  }
  double count = static_cast<double>(map.coeffs.size());
  const std::size_t row_bytes = static_cast<std::size_t>(map.width) * 3 * t;
  report.file_bytes = data0 + row_bytes * static_cast<std::size_t>(full_height);
  if (peers == nullptr) {
    std::string blob = std::move(head);
    blob.append(reinterpret_cast<const char*>(bytes.data()), bytes.size());
    write_file_atomic(path, blob);
  } else {
    // Rank 0 creates the temporary and writes the header; every process its rows.
    std::optional<AtomicOutput> out;
    RawFile file = open_shared_output(peers, path, head, &out);
    file.write_at(bytes.data(), bytes.size(),
                  data0 + row_bytes * static_cast<std::size_t>(row_offset), path);
    file.close(path);
    peers->agree(true, where(path));
    double mx = report.max_coeff_error;
    double sums[2] = {sum_sq, count};
    peers->max(&mx, 1);
    peers->sum(sums, 2);
    report.max_coeff_error = mx;
    sum_sq = sums[0];
    count = sums[1];
    peers->finish();
    if (out) out->commit();
  }
  report.rms_coeff_error = std::sqrt(sum_sq / count);
  return report;
}

}  // namespace

RtiWriteReport write_rti(const fs::path& path, const CoefficientMap& map) {
  return write_rti_rows(path, map, {});
}

namespace {

// Reads one header line (without its end, CR stripped); false at end of file.
bool next_line(const std::string& data, std::size_t* pos, std::string* line) {
  if (*pos >= data.size()) return false;
  const std::size_t end = data.find('\n', *pos);
  if (end == std::string::npos) return false;  // a header line must be terminated
  *line = data.substr(*pos, end - *pos);
  if (!line->empty() && line->back() == '\r') line->pop_back();
  *pos = end + 1;
  return true;
}

std::vector<long long> parse_ints(const fs::path& path, const std::string& line, int expected,
                                  const char* what) {
  std::istringstream in(line);
  std::vector<long long> v;
  long long x = 0;
  while (in >> x) v.push_back(x);
  in.clear();
  std::string rest;
  in >> rest;
  if (static_cast<int>(v.size()) != expected || !rest.empty()) {
    throw Error(where(path) + ": expected " + what + ", got '" + excerpt(line) + "'");
  }
  return v;
}

}  // namespace

CoefficientMap read_rti(const fs::path& path, ColourSpace colour_space) {
  // Regular files only (a device never ends), read only if they fit in memory.
  const std::uintmax_t file_bytes =
      checked_input_size(path, std::numeric_limits<std::uintmax_t>::max(), ".rti file");
  check_allocation(path, file_bytes, "the file's bytes");
  std::ifstream f(path, std::ios::binary);
  if (!f) throw Error(where(path) + ": cannot open the file");
  const std::string data((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  if (f.bad()) throw Error(where(path) + ": cannot read the file");
  std::size_t pos = 0;
  std::string line;
  do {
    if (!next_line(data, &pos, &line)) {
      throw Error(where(path) + ": not an .rti file (the header ends before the RTI type)");
    }
  } while (!line.empty() && line[0] == '#');
  const long long type = parse_ints(path, line, 1, "the RTI type (3 = HSH)")[0];
  if (type != 3) {
    throw Error(where(path) + ": " + unsupported_variant("RTI type " + std::to_string(type)));
  }
  if (!next_line(data, &pos, &line)) throw Error(where(path) + ": the header ends early");
  const auto size = parse_ints(path, line, 3, "'width height components'");
  if (size[0] <= 0 || size[1] <= 0 || size[0] > kMaxSide || size[1] > kMaxSide ||
      size[0] * size[1] > kMaxTexels) {
    throw Error(where(path) + ": bad size " + std::to_string(size[0]) + " x " +
                std::to_string(size[1]));
  }
  if (size[2] != 3) {
    throw Error(where(path) + ": " + std::to_string(size[2]) +
                " colour components; only 3 are supported");
  }
  if (!next_line(data, &pos, &line)) throw Error(where(path) + ": the header ends early");
  const auto basis = parse_ints(path, line, 3, "'terms basis-type element-size'");
  const int t = hsh_order(static_cast<int>(basis[0])) ? static_cast<int>(basis[0]) : 0;
  if (t == 0) {
    throw Error(where(path) + ": " + std::to_string(basis[0]) +
                " basis terms; HSH files have 4, 9 or 16");
  }
  if (basis[2] != 1) {
    throw Error(where(path) + ": element size " + std::to_string(basis[2]) +
                " is not supported (only 1 byte)");
  }
  const int w = static_cast<int>(size[0]);
  const int h = static_cast<int>(size[1]);
  // The declared size is checked against the bytes present and the memory available before
  // the map is allocated (a short file must not cost gigabytes).
  const std::size_t floats = 2 * sizeof(float) * static_cast<std::size_t>(t);
  const std::uint64_t coeff_count =
      checked_multiply(path, static_cast<std::uint64_t>(w) * static_cast<std::uint64_t>(h),
                       3 * static_cast<std::uint64_t>(t));
  const std::uint64_t expected = floats + coeff_count;
  const std::size_t present = data.size() - pos;
  if (present < expected) {
    throw Error(where(path) + ": the binary block is too short: " + std::to_string(w) + " x " +
                std::to_string(h) + " x " + std::to_string(t) + " terms need " +
                std::to_string(expected) + " bytes, found " + std::to_string(present));
  }
  if (present > expected) {
    throw Error(where(path) + ": " + std::to_string(present - expected) +
                " bytes after the binary block (a damaged file, or a header that does not "
                "describe it)");
  }
  check_allocation(path, checked_multiply(path, coeff_count, sizeof(float)),
                   "the " + std::to_string(w) + " x " + std::to_string(h) + " x " +
                       std::to_string(t) + "-term coefficients");
  CoefficientMap map({w, h, hsh_basis_of_terms(t), ColourModel::kRGB, colour_space});
  std::vector<float> scale(t), bias(t);
  std::memcpy(scale.data(), data.data() + pos, sizeof(float) * t);
  std::memcpy(bias.data(), data.data() + pos + sizeof(float) * t, sizeof(float) * t);
  for (int k = 0; k < t; ++k) {
    if (!std::isfinite(scale[k]) || !std::isfinite(bias[k])) {
      throw Error(where(path) + ": scale or bias " + std::to_string(k) + " is not finite");
    }
  }
  const auto* bytes = reinterpret_cast<const unsigned char*>(data.data() + pos + floats);
  for (std::size_t i = 0; i < map.coeffs.size(); ++i) {
    const auto k = static_cast<int>(i % static_cast<std::size_t>(t));
    map.coeffs[i] = static_cast<float>(bytes[i] / 255.0 * scale[k] + bias[k]);
  }
  return map;
}

bool looks_like_rti(const fs::path& path) {
  std::ifstream f(path, std::ios::binary);
  char head[8] = {};
  if (!f.read(head, sizeof head) && f.gcount() < 2) return false;
  if (head[0] == '#') return true;
  return head[0] == '3' && (head[1] == '\n' || head[1] == '\r' || head[1] == ' ');
}

RtiSummary summarise_rti(const std::filesystem::path& path) {
  const CoefficientMap map = read_rti(path);
  RtiSummary out;
  out.width = map.width;
  out.height = map.height;
  out.terms = map.terms();
  out.order = hsh_order(map.terms());
  const auto terms = static_cast<std::size_t>(map.terms());
  out.coeff_min.assign(terms, std::numeric_limits<double>::infinity());
  out.coeff_max.assign(terms, -std::numeric_limits<double>::infinity());
  for (std::size_t i = 0; i < map.coeffs.size(); ++i) {
    const std::size_t k = i % terms;
    out.coeff_min[k] = std::min(out.coeff_min[k], static_cast<double>(map.coeffs[i]));
    out.coeff_max[k] = std::max(out.coeff_max[k], static_cast<double>(map.coeffs[i]));
  }
  out.file_bytes = static_cast<std::size_t>(std::filesystem::file_size(path));
  out.file_bytes_per_texel = 3 * map.terms();
  out.map_bytes_per_texel = 3 * map.terms() * static_cast<int>(sizeof(float));
  return out;
}

void RtiWriter::begin(const CoefficientLayout& layout) {
  if (share_.collective != nullptr &&
      (share_.row_offset < 0 || share_.full_height < layout.height ||
       share_.row_offset > share_.full_height - layout.height)) {
    throw std::logic_error("RtiWriter: rows outside the distributed file's height");
  }
  if (layout.basis == Basis::kPtm || layout.model != ColourModel::kRGB) {
    throw Error(where(path_) + ": an .rti holds an HSH basis in three channels, not " +
                std::string(to_string(layout.basis)) + " " + std::string(to_string(layout.model)));
  }
  sink_.begin(layout);
}

void RtiWriter::write_rows(int y0, int rows, const float* coeffs, const float* colour) {
  sink_.write_rows(y0, rows, coeffs, colour);
}

void RtiWriter::end() {
  report_ = write_rti_rows(path_, map_, share_);
  map_ = CoefficientMap();  // the memory back
}

}  // namespace ptmkit::texture
