// Hemispherical harmonics (HSH): a basis of functions of the light direction over the upper
// hemisphere, used by the fit (fit/basis.h) and by .rti textures (texture/rti.h).
//
// The HSH basis (Gautron, Krivanek, Pattanaik, Bouatouch, "A novel hemispherical basis for
// accurate and efficient rendering", EGSR 2004), in the form and order the .rti viewers
// evaluate it. With the light direction (x, y, z) in the light frame (x right, y up the image,
// z toward the camera), theta = min(acos z, pi/2 - 0.04), phi = atan2(y, x), c = cos theta,
// s = sqrt(c - c^2):
//   order 2 (4 terms):
//     h0 = 1/sqrt(2 pi)              h1 = sqrt(6/pi) cos(phi) s
//     h2 = sqrt(3/(2 pi)) (2c - 1)   h3 = sqrt(6/pi) sin(phi) s
//   order 3 (9 terms) adds:
//     h4 = sqrt(30/pi) cos(2 phi) (c^2 - c)      h5 = sqrt(30/pi) cos(phi) (2c - 1) s
//     h6 = sqrt(5/(2 pi)) (6c^2 - 6c + 1)        h7 = sqrt(30/pi) sin(phi) (2c - 1) s
//     h8 = sqrt(30/pi) sin(2 phi) (c^2 - c)
//   order 4 (16 terms) adds:
//     h9  = 2 sqrt(35/pi) cos(3 phi) s^3          h10 = sqrt(210/pi) cos(2 phi) (2c - 1)(c^2 - c)
//     h11 = 2 sqrt(21/pi) cos(phi) s (5c^2 - 5c + 1)
//     h12 = sqrt(7/(2 pi)) (20c^3 - 30c^2 + 12c - 1)
//     h13 = 2 sqrt(21/pi) sin(phi) s (5c^2 - 5c + 1)
//     h14 = sqrt(210/pi) sin(2 phi) (2c - 1)(c^2 - c)  h15 = 2 sqrt(35/pi) sin(3 phi) s^3
// The clamp of theta at pi/2 - 0.04 rad (87.7 degrees) is the viewers' (it keeps s away from
// the horizon); the fit uses the same clamp so fit and viewer agree for every light.
#pragma once

#include <Eigen/Core>

namespace ptmkit {

// The first `terms` (4, 9 or 16) HSH basis functions at `dir` (normalised here; must be
// non-zero and finite, z may be anything: theta is clamped as above).
void hsh_basis(int terms, const Eigen::Vector3d& dir, double* out);

}  // namespace ptmkit
