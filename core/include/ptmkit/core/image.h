// Images in memory: a non-owning view with an explicit stride, and an owning float image.
//
// Pixel values are floats, interleaved by channel. Integer files are normalised on reading
// (8-bit / 255, 16-bit / 65535), so 1.0 is "full scale"; float files keep their values (HDR
// input may exceed 1). The colour space says what the values are: sRGB-encoded (as most
// cameras write JPEG and PNG) or linear. Nothing in the library converts silently.
#pragma once

#include <cassert>
#include <cstddef>
#include <string_view>
#include <vector>

namespace ptmkit {

enum class ColourSpace {
  kLinear,  // values proportional to radiance
  kSRGB,    // values encoded with the sRGB transfer curve
};
[[nodiscard]] std::string_view to_string(ColourSpace space);

// Non-owning view of an interleaved image. `stride` is the distance between the starts of
// two consecutive rows, in elements of T (not bytes); it is at least width * channels.
template <class T>
struct ImageView {
  T* data = nullptr;
  int width = 0;
  int height = 0;
  int channels = 0;
  std::ptrdiff_t stride = 0;
  ColourSpace colour_space = ColourSpace::kLinear;

  [[nodiscard]] bool empty() const { return data == nullptr || width <= 0 || height <= 0; }
  [[nodiscard]] T* row(int y) const {
    assert(y >= 0 && y < height);
    return data + static_cast<std::ptrdiff_t>(y) * stride;
  }
  [[nodiscard]] T& at(int x, int y, int c) const {
    assert(x >= 0 && x < width && c >= 0 && c < channels);
    return row(y)[static_cast<std::ptrdiff_t>(x) * channels + c];
  }
  // A view of a rectangle of this one, sharing its pixels.
  [[nodiscard]] ImageView crop(int x0, int y0, int w, int h) const {
    assert(x0 >= 0 && y0 >= 0 && x0 + w <= width && y0 + h <= height);
    return {data + static_cast<std::ptrdiff_t>(y0) * stride +
                static_cast<std::ptrdiff_t>(x0) * channels,
            w,
            h,
            channels,
            stride,
            colour_space};
  }
  operator ImageView<const T>() const {  // NOLINT: views convert to read-only views freely
    return {data, width, height, channels, stride, colour_space};
  }
};

using ImageViewF = ImageView<float>;
using ConstImageViewF = ImageView<const float>;

// Owning float image, tightly packed (stride == width * channels).
class Image {
 public:
  Image() = default;
  Image(int width, int height, int channels, ColourSpace colour_space = ColourSpace::kLinear,
        float fill = 0.0f);

  [[nodiscard]] int width() const { return width_; }
  [[nodiscard]] int height() const { return height_; }
  [[nodiscard]] int channels() const { return channels_; }
  [[nodiscard]] bool empty() const { return pixels_.empty(); }
  [[nodiscard]] ColourSpace colour_space() const { return colour_space_; }
  void set_colour_space(ColourSpace space) { colour_space_ = space; }

  [[nodiscard]] float* data() { return pixels_.data(); }
  [[nodiscard]] const float* data() const { return pixels_.data(); }
  [[nodiscard]] std::size_t size() const { return pixels_.size(); }
  [[nodiscard]] float& at(int x, int y, int c) { return pixels_[index(x, y, c)]; }
  [[nodiscard]] float at(int x, int y, int c) const { return pixels_[index(x, y, c)]; }
  [[nodiscard]] float* row(int y) { return pixels_.data() + index(0, y, 0); }
  [[nodiscard]] const float* row(int y) const { return pixels_.data() + index(0, y, 0); }

  [[nodiscard]] ImageViewF view();
  [[nodiscard]] ConstImageViewF view() const;

 private:
  [[nodiscard]] std::size_t index(int x, int y, int c) const {
    assert(x >= 0 && x < width_ && y >= 0 && y < height_ && c >= 0 && c < channels_);
    return (static_cast<std::size_t>(y) * width_ + x) * channels_ + c;
  }
  int width_ = 0;
  int height_ = 0;
  int channels_ = 0;
  ColourSpace colour_space_ = ColourSpace::kLinear;
  std::vector<float> pixels_;
};

}  // namespace ptmkit
