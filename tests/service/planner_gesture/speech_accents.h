// Pitch accents of a real LibriVox clip (tests/data/speech) from the prosody
// pipeline, as the planner's gesture RPCs take them.
#pragma once

#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "common/audio/decode.h"
#include "kinemo/common/v1/speech.pb.h"
#include "services/prosody/core/pipeline.h"

namespace kinemo::planner::testing {

inline std::vector<common::v1::PitchAccent> SpeechAccents(double* duration_s = nullptr) {
  auto audio = audio::DecodeAudioFile(std::string(KINEMO_TEST_DATA_DIR) +
                                      "/speech/sense_and_sensibility_01_austen_64kb-0890.wav");
  EXPECT_TRUE(audio.ok());
  if (!audio.ok()) return {};
  auto r = prosody::RunPipeline(audio->samples, audio->sample_rate_hz, {}, nullptr);
  EXPECT_TRUE(r.ok());
  if (!r.ok()) return {};
  if (duration_s != nullptr) *duration_s = r->prosody.duration_s;
  std::vector<common::v1::PitchAccent> out;
  for (const auto& a : r->prosody.accents) {
    common::v1::PitchAccent p;
    p.set_time_s(a.time_s);
    p.set_strength(a.strength);
    p.set_psi(a.psi);
    p.set_syllable_start_s(a.syllable_start_s);
    p.set_syllable_end_s(a.syllable_end_s);
    out.push_back(p);
  }
  return out;
}

}  // namespace kinemo::planner::testing
