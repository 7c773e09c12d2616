// Numeric tolerances shared by several test files, each with its derivation. A tolerance used
// by one file only is defined in that file.
#pragma once

namespace ptmkit::test {

// float32 rounding of values up to about 1 (2^-24 ~ 6e-8 each), with room for a few operations.
inline constexpr double kFloatTol = 1e-6;

// Relit images in grey levels: float32 relighting scaled by 255 (~1.5e-5 a value), with room.
inline constexpr double kRelitGreySlack = 1e-3;

}  // namespace ptmkit::test
