// Tolerances shared by several test files, each with its derivation. A tolerance used by one
// file only is named at the top of that file.
#pragma once

namespace ptmkit::test {

// A short double computation on values up to a few hundred (an ulp is at most 5.7e-14): tens
// of ulps of rounding or more.
inline constexpr double kDoubleRoundoff = 1e-12;
// Double rounding amplified by a least-squares solve (eps 2.2e-16 times its condition number
// and the data's magnitude) or by a long computation on values in the hundreds.
inline constexpr double kDoubleSolveRoundoff = 1e-9;
// Float values of order 1 (eps 1.2e-7): under ten ulps of rounding.
inline constexpr double kFloatRoundoff = 1e-6;
// Float sums of tens of products of order 1: about a hundred ulps of 1.2e-7.
inline constexpr double kFloatSumRoundoff = 1e-5;
// Relit images in grey levels: float relighting scaled by 255 (about 1.5e-5 a value), with
// room for the evaluation's few operations.
inline constexpr double kRelitGreySlack = 1e-3;
// Half a step of an 8-bit encoding of [0, 1]: the most round-to-nearest moves a value.
inline constexpr double kHalf8BitStep = 0.5 / 255.0;
// Half a step of a 16-bit encoding of [0, 1].
inline constexpr double kHalf16BitStep = 0.5 / 65535.0;
// The dome49 layout's cond(A), a property of the layout (docs/TARGETS.md: 5.3 +- 0.2).
inline constexpr double kDome49Condition = 5.3;
inline constexpr double kDome49ConditionTol = 0.2;

}  // namespace ptmkit::test
