// Visemes judged against a forced alignment, frame by frame and per phone:
// what `kinemo face loto` reports (docs/face.md, "Judged against the captured
// face"). Plain C++ over the face's own types.
#pragma once

#include <span>

#include "common/face/face_frame.h"

namespace kinemo::face {

struct VisemeScores {
  // Frame level. accuracy: speech frames whose dominant category is the
  // reference phone's; chance: the most frequent reference category's share
  // of speech frames; bpm_closed: B/P/M frames whose dominant category is
  // B_P_M (the lips closed); closed_outside_bpm: speech frames of other phones
  // shown closed; pauses_at_rest: pause frames whose dominant OVR viseme is sil.
  double accuracy = 0, chance = 0, bpm_closed = 0, closed_outside_bpm = 0, pauses_at_rest = 0;
  // Phone level. A b/p/m phone is a run of reference B/P/M frames, a closure
  // a run of closed frames. bpm_phones_closed: b/p/m phones with at least one
  // closed frame; spurious_closures_per_min: closures that touch no B/P/M
  // frame (within one frame either side), per minute of the track (from its
  // first frame's time to its last's).
  double bpm_phones_closed = 0, spurious_closures_per_min = 0;
  int speech_frames = 0, bpm_frames = 0, pause_frames = 0, bpm_phones = 0, closures = 0, spurious_closures = 0;
};

// `reference[i]`: the forced-aligned phone's class (PhoneClass; kSil in a
// pause) at track.frames[i].time_s. Frames beyond the shorter of the two are
// not scored. Shares with nothing to count are 0.
VisemeScores ScoreVisemes(std::span<const int> reference, const FaceTrack& track);

}  // namespace kinemo::face
