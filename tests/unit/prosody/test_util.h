// Helpers of the prosody tests: the real speech in tests/data.
#pragma once

#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "common/audio/decode.h"

namespace kinemo::prosody::testing {

inline std::string DataPath(const std::string& relative) {
  return std::string(KINEMO_TEST_DATA_DIR) + "/" + relative;
}

// LibriVox clips (16 kHz mono) that have Praat references in tests/data/prosody.
inline std::vector<std::string> ReferenceClips() {
  std::vector<std::string> clips;
  for (const auto& entry : std::filesystem::directory_iterator(DataPath("prosody"))) {
    const std::string name = entry.path().filename().string();
    const std::string suffix = ".praat_pitch.csv";
    if (name.size() > suffix.size() && name.ends_with(suffix)) {
      const std::string stem = name.substr(0, name.size() - suffix.size());
      if (std::filesystem::exists(DataPath("speech/" + stem + ".wav"))) clips.push_back(stem);
    }
  }
  std::sort(clips.begin(), clips.end());
  return clips;
}

inline audio::DecodedAudio LoadClip(const std::string& stem) {
  auto decoded = audio::DecodeAudioFile(DataPath("speech/" + stem + ".wav"));
  if (!decoded.ok()) {
    std::fprintf(stderr, "%s\n", std::string(decoded.status().message()).c_str());
    return {};
  }
  return *std::move(decoded);
}

struct CsvRow {
  double time_s = 0;
  double value = 0;
};

inline std::vector<CsvRow> ReadCsv(const std::string& path) {
  std::vector<CsvRow> rows;
  FILE* f = std::fopen(path.c_str(), "r");
  if (!f) return rows;
  char line[256];
  if (!std::fgets(line, sizeof line, f)) {
    std::fclose(f);
    return rows;
  }
  CsvRow r;
  while (std::fscanf(f, "%lf,%lf", &r.time_s, &r.value) == 2) rows.push_back(r);
  std::fclose(f);
  return rows;
}

}  // namespace kinemo::prosody::testing
