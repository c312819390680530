// Viseme weight tracks from timed ARPAbet phones (CMU Sphinx) and pitch
// accents (thesis §4.5.1-4.5.2, Table 4.5).
//
// Each phone maps to one of 15 categories (Table 4.5, MRPA symbols read as
// their ARPAbet equivalents; ARPAbet-only symbols: AXR/ER -> EY, IX -> AO,
// UX -> W_UW, DX/NX -> N_D_T_L; silence, Sphinx fillers and noise -> PAU).
// Frame k (time k·frame_time_s) gets weight 1 on the category of the phone
// containing it (PAU between phones), except near a boundary b between
// phones p and q: within h = min(coarticulation_s / 2, |p| / 2, |q| / 2) of b
// the two categories cross-fade linearly (0.5 each at b), so the weights sum
// to 1 and the dominant category is always the phone under the frame.
//
// Emphasis: inside a vowel phone that overlaps an accented syllable (the
// accent's syllable span, or the vowel containing the PAPT when the span is
// unknown), emphasis = 2·s' − 1 with s' = clamp(strength + face_emphasis,
// 0, 1): −1 = the low-emphatic variant, 0 = neutral, +1 = high-emphatic; 0
// elsewhere.
#pragma once

#include <array>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "common/status/status.h"

namespace kinemo::planner::gesture {

// Category order = the proto enum VisemeCategory minus 1.
enum class Viseme {
  kPau, kR, kKGNg, kAa, kFV, kChShJh, kAo, kOw, kNDTL, kEy, kThDh, kSZZh, kBPM, kHh, kWUw
};
inline constexpr int kNumVisemes = 15;
std::string_view VisemeName(Viseme v);
bool IsVowelViseme(Viseme v);

// Phone -> category (case-insensitive, stress digits ignored); false (and
// kPau) when the phone is not in the table.
bool PhoneToViseme(std::string_view phone, Viseme* out);

struct TimedPhone {
  std::string phone;
  double start_s = 0, end_s = 0;
};

struct VisemeAccent {
  double papt_s = 0;
  double strength = 0;
  double syllable_start_s = 0, syllable_end_s = 0;  // 0, 0 = unknown
};

struct VisemeParams {
  double frame_time_s = 1.0 / 30.0;
  double coarticulation_s = 0.04;
  double face_emphasis = 0;  // [-1, 1]
  double duration_s = 0;     // 0 = end of the last phone
  double max_duration_s = 3600;
};

struct VisemeFrame {
  double time_s = 0;
  std::array<double, kNumVisemes> weights{};
  double emphasis = 0;
};

struct VisemeTrack {
  double frame_time_s = 0;
  std::vector<VisemeFrame> frames;
  std::vector<std::string> unknown_phones;  // distinct, in order of appearance
};

// INVALID_ARGUMENT (naming the field) for phones out of order or
// overlapping, negative or NaN times, params out of range.
StatusOr<VisemeTrack> ComputeVisemes(std::span<const TimedPhone> phones, std::span<const VisemeAccent> accents,
                                     const VisemeParams& params);

// {"frame_time_s", "categories": [...], "frames": [{"time_s", "weights", "emphasis"}],
//  "unknown_phones"}.
std::string VisemesToJson(const VisemeTrack& track);
// Header: time_s,emphasis,PAU,R,... then one row per frame.
std::string VisemesToCsv(const VisemeTrack& track);

}  // namespace kinemo::planner::gesture
