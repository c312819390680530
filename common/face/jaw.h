// The SMPL-X `jaw` joint and the face track's jaw opening (docs/face.md).
//
// Measured on BEAT2's captured faces (tests/data/paired/beat2, both takes,
// 3710 frames; the joint's CHANNELS are Zrotation Xrotation Yrotation): the
// jaw's rotation, as its (Z, X, Y) Euler angles in degrees, moves along one
// direction, the hinge, which holds 96.9 % of its variance (principal
// component): (0.0954, 0.9954, 0.0044), mostly X, positive = opening. The
// jaw at rest is taken at the 2nd percentile along it: (-0.1292, -0.1884,
// -0.0923). jaw_open_deg = (angles - rest) · hinge; the joint is written as
// rest + jaw_open_deg * hinge. Speech moves it 0 to about 4 degrees.
#pragma once

#include <array>

namespace kinemo::face {

// The speaker's wide opening in speech: the 95th percentile of the captured
// jaw_open_deg over both BEAT2 takes (3710 frames: median 1.34, 95th 2.65,
// 99th 3.35 degrees). A rig draws a vowel's mouth shape open by
// jaw_open_deg / this (common/retarget/face_map.h).
inline constexpr double kSmplxJawSpeechWideDeg = 2.65;

inline constexpr std::array<double, 3> kSmplxJawHingeZxy = {0.0954, 0.9954, 0.0044};
inline constexpr std::array<double, 3> kSmplxJawRestZxyDeg = {-0.1292, -0.1884, -0.0923};

// (Z, X, Y) rotation of the jaw joint, in degrees -> opening, in degrees.
inline double SmplxJawOpeningDeg(const std::array<double, 3>& zxy_deg) {
  double s = 0;
  for (int i = 0; i < 3; ++i) s += (zxy_deg[i] - kSmplxJawRestZxyDeg[i]) * kSmplxJawHingeZxy[i];
  return s;
}

// Opening, in degrees -> (Z, X, Y) rotation of the jaw joint, in degrees.
inline std::array<double, 3> SmplxJawZxyDeg(double opening_deg) {
  std::array<double, 3> out;
  for (int i = 0; i < 3; ++i) out[i] = kSmplxJawRestZxyDeg[i] + opening_deg * kSmplxJawHingeZxy[i];
  return out;
}

}  // namespace kinemo::face
