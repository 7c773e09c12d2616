// Pictures of a sphere calibration: the overlay of the sphere and one light's highlight on
// its image, and the polar plot of the light directions.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <string>

#include <opencv2/imgproc.hpp>

#include "ptmkit/calib/sphere.h"
#include "ptmkit/core/error.h"
#include "sphere_detail.h"

namespace ptmkit::calib {

namespace {

cv::Mat to_bgr8(const Image& img) {
  cv::Mat out(img.height(), img.width(), CV_8UC3);
  for (int y = 0; y < img.height(); ++y) {
    auto* row = out.ptr<cv::Vec3b>(y);
    for (int x = 0; x < img.width(); ++x) {
      for (int c = 0; c < 3; ++c) {
        const float v = img.at(x, y, img.channels() >= 3 ? 2 - c : 0);
        row[x][c] = static_cast<unsigned char>(std::lround(std::clamp(v, 0.0f, 1.0f) * 255.0f));
      }
    }
  }
  return out;
}

cv::Point to_point(const Eigen::Vector2d& p, int shift) {
  return {static_cast<int>(std::lround(p.x() * (1 << shift))),
          static_cast<int>(std::lround(p.y() * (1 << shift)))};
}

}  // namespace

Image sphere_overlay(const Image& image, const SphereReport& report, std::size_t light_index,
                     double scale, int text_row) {
  cv::Mat m = to_bgr8(image);
  constexpr int kShift = 4;  // sub-pixel drawing
  const Circle& s = report.sphere;
  const Eigen::Vector2d centre = s.centre_px * scale;
  cv::circle(m, to_point(centre, kShift), static_cast<int>(s.radius_px * scale * (1 << kShift)),
             cv::Scalar(255, 200, 0), 1, cv::LINE_AA, kShift);
  cv::drawMarker(m, to_point(centre, 0), cv::Scalar(255, 200, 0), cv::MARKER_CROSS, 9, 1);
  const SphereLight& l = report.lights.at(light_index);
  // Green: used; orange: used but doubtful (an outlier); red: not used.
  const cv::Scalar colour = !l.found    ? cv::Scalar(0, 0, 255)
                            : l.outlier ? cv::Scalar(0, 150, 255)
                                        : cv::Scalar(0, 220, 0);
  if (l.peak > 0.0 && (l.highlight_px.x() != 0.0 || l.highlight_px.y() != 0.0)) {
    const Eigen::Vector2d h = l.highlight_px * scale;
    cv::circle(m, to_point(h, kShift), 6 << kShift, colour, 1, cv::LINE_AA, kShift);
    cv::drawMarker(m, to_point(h, 0), colour, cv::MARKER_CROSS, 5, 1);
  }
  std::string text = std::to_string(light_index) + ": " + l.image.filename().string();
  if (l.found) {
    char buf[48];
    std::snprintf(buf, sizeof(buf), " confidence %.2f", l.confidence);
    text += buf;
  }
  if (!l.found || l.outlier) text += " - " + l.flag;
  cv::putText(m, text, cv::Point(6, 18 + 16 * text_row), cv::FONT_HERSHEY_SIMPLEX, 0.45, colour, 1,
              cv::LINE_AA);
  return detail::from_bgr8(m);
}

Image light_polar_plot(const SphereReport& report, int size_px) {
  if (size_px < 100) throw Error("polar plot: size must be at least 100 pixels");
  cv::Mat m(size_px, size_px, CV_8UC3, cv::Scalar(255, 255, 255));
  const cv::Point centre(size_px / 2, size_px / 2);
  const double rim = 0.44 * size_px;
  for (int el = 0; el < 90; el += 30) {
    const int r = static_cast<int>(rim * (90.0 - el) / 90.0);
    cv::circle(m, centre, r, cv::Scalar(200, 200, 200), 1, cv::LINE_AA);
    cv::putText(m, std::to_string(el), centre + cv::Point(r + 2, -2), cv::FONT_HERSHEY_SIMPLEX,
                0.35, cv::Scalar(150, 150, 150), 1, cv::LINE_AA);
  }
  cv::line(m, centre - cv::Point(static_cast<int>(rim), 0),
           centre + cv::Point(static_cast<int>(rim), 0), cv::Scalar(220, 220, 220));
  cv::line(m, centre - cv::Point(0, static_cast<int>(rim)),
           centre + cv::Point(0, static_cast<int>(rim)), cv::Scalar(220, 220, 220));
  int flagged_row = 0;
  for (std::size_t i = 0; i < report.lights.size(); ++i) {
    const SphereLight& l = report.lights[i];
    if (!l.found) {
      cv::putText(m, std::to_string(i) + ": " + l.flag.substr(0, 60),
                  cv::Point(6, size_px - 8 - 14 * flagged_row++), cv::FONT_HERSHEY_SIMPLEX, 0.38,
                  cv::Scalar(0, 0, 255), 1, cv::LINE_AA);
      continue;
    }
    const double el = std::asin(std::clamp(l.direction.z(), -1.0, 1.0)) * 180.0 / std::numbers::pi;
    const double az = std::atan2(l.direction.y(), l.direction.x());
    const double r = rim * (90.0 - el) / 90.0;
    // Light frame y points up the image; the plot's y axis points down.
    const cv::Point p = centre + cv::Point(static_cast<int>(std::lround(r * std::cos(az))),
                                           static_cast<int>(std::lround(-r * std::sin(az))));
    cv::circle(m, p, 4, cv::Scalar(180, 90, 0), cv::FILLED, cv::LINE_AA);
    cv::putText(m, std::to_string(i), p + cv::Point(5, -4), cv::FONT_HERSHEY_SIMPLEX, 0.38,
                cv::Scalar(60, 60, 60), 1, cv::LINE_AA);
  }
  cv::putText(m, "light directions (elevation rings 0/30/60, x right, y up)", cv::Point(6, 16),
              cv::FONT_HERSHEY_SIMPLEX, 0.42, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  return detail::from_bgr8(m);
}

namespace detail {

Image from_bgr8(const cv::Mat& m) {
  Image out(m.cols, m.rows, 3, ColourSpace::kSRGB);
  for (int y = 0; y < m.rows; ++y) {
    const auto* row = m.ptr<cv::Vec3b>(y);
    for (int x = 0; x < m.cols; ++x) {
      for (int c = 0; c < 3; ++c) out.at(x, y, c) = static_cast<float>(row[x][2 - c]) / 255.0f;
    }
  }
  return out;
}

}  // namespace detail

}  // namespace ptmkit::calib
