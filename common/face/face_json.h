// The viseme file (`kinemo animate --visemes V.json`, `kinemo retarget
// --visemes V.json`): a face track as JSON, every channel of FaceFrame.
//
//   {"frame_time_s": 0.0333,
//    "categories": ["VISEME_CATEGORY_PAU", ...],     15 thesis categories (Table 4.5)
//    "ovr_visemes": ["sil", "PP", ..., "ou"],        15 OVR / OpenXR visemes
//    "frames": [{"time_s": 0,
//                "weights": [15 category weights],   each in [0, 1], summing to 1
//                "emphasis": 0,                      -1 .. 1 (thesis §4.5.2)
//                "ovr": [15 OVR weights],            each in [0, 1], summing to 1
//                "jaw_deg": 0,                       jaw opening about its hinge, degrees
//                "blink": 0, "blink_left": 0, "blink_right": 0,   eye closure 0 .. 1
//                "brow": 0,                          brows raised 0 .. 1
//                "expression": "neutral",            neutral happy angry sad surprised
//                "expression_weight": 0}, ...]}      0 .. 1
//
// `blink` is the mean of both eyes. The layout before the face track
// (frame_time_s, categories, frames[].time_s / weights / emphasis) is the same
// file without the newer members; the reader accepts it, taking OVR weights
// from the categories (CategoriesToOvr) and zeros for the rest. Categories
// may be named with or without the VISEME_CATEGORY_ prefix, in any order
// (the weights are read in the file's order).
#pragma once

#include <string>
#include <string_view>

#include "common/face/face_frame.h"
#include "common/status/status.h"

namespace kinemo::face {

// Limits of the reader (outside input).
inline constexpr double kMaxFaceTrackS = 3600;           // last frame's time_s
inline constexpr std::size_t kMaxFaceFrames = 1000000;   // frames in one file
inline constexpr double kMaxJawDeg = 90;                 // |jaw_deg|

// The file's text (one line of JSON). Numbers are rounded to 4 decimals.
std::string FaceTrackToJson(const FaceTrack& track);

// Reads a viseme file. Errors are INVALID_ARGUMENT and start with `name`
// (the file's name) and the member: "V.json: frames[3].ovr[2]: must be in
// [0, 1], got 1.5". Checked: frame_time_s in (0, 1]; at most kMaxFaceFrames
// frames, time_s finite, in [0, kMaxFaceTrackS] and non-decreasing; weights
// and ovr 15 numbers in [0, 1] each; jaw_deg within ±kMaxJawDeg; blinks,
// brow and expression_weight in [0, 1]; emphasis in [-1, 1]; expression one
// of the five names; categories and ovr_visemes the 15 names each, once.
StatusOr<FaceTrack> FaceTrackFromJson(std::string_view text, std::string_view name);

}  // namespace kinemo::face
