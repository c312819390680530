// Compares kinemo's pitch and intensity with Praat's, frame by frame, on
// Praat's own frame grids (see praat_reference.praat and praat_compare.sh).
//
//   prosody_praat_compare AUDIO.wav PITCH.csv INTENSITY.csv
//
// Prints one JSON line: frames voiced in both within 50 cents, voicing
// agreement, intensity within 1 dB.
#include <sndfile.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "services/prosody/core/analyzer.h"

namespace {

struct Row {
  double t, v;
};

std::vector<Row> ReadCsv(const std::string& path) {
  std::ifstream in(path);
  std::string line;
  std::vector<Row> rows;
  std::getline(in, line);
  while (std::getline(in, line)) {
    Row r;
    if (std::sscanf(line.c_str(), "%lf,%lf", &r.t, &r.v) == 2) rows.push_back(r);
  }
  return rows;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 4) {
    std::fprintf(stderr, "usage: %s AUDIO PITCH.csv INTENSITY.csv\n", argv[0]);
    return 2;
  }
  SF_INFO info{};
  SNDFILE* f = sf_open(argv[1], SFM_READ, &info);
  if (!f) {
    std::fprintf(stderr, "%s: %s\n", argv[1], sf_strerror(nullptr));
    return 1;
  }
  std::vector<float> inter(static_cast<size_t>(info.frames) * info.channels);
  sf_readf_float(f, inter.data(), info.frames);
  sf_close(f);
  std::vector<float> mono(info.frames);
  for (sf_count_t i = 0; i < info.frames; ++i) {
    float s = 0;
    for (int c = 0; c < info.channels; ++c) s += inter[i * info.channels + c];
    mono[i] = s / info.channels;
  }
  const auto pitch = ReadCsv(argv[2]);
  const auto inten = ReadCsv(argv[3]);
  kinemo::prosody::AnalysisOptions options;
  auto frames = kinemo::prosody::AnalyzeFrames(
      mono, info.samplerate, options, {pitch.empty() ? 0.0 : pitch[0].t, static_cast<int>(pitch.size())});
  auto iframes = kinemo::prosody::AnalyzeFrames(
      mono, info.samplerate, options, {inten.empty() ? 0.0 : inten[0].t, static_cast<int>(inten.size())});
  if (!frames.ok() || !iframes.ok()) {
    std::fprintf(stderr, "analysis failed\n");
    return 1;
  }
  int both = 0, within = 0, agree = 0;
  for (size_t i = 0; i < pitch.size(); ++i) {
    const bool pv = pitch[i].v > 0;
    const bool kv = (*frames)[i].voiced;
    agree += pv == kv;
    if (pv && kv) {
      ++both;
      const double cents = 1200 * std::log2((*frames)[i].f0_hz / pitch[i].v);
      within += std::fabs(cents) <= 50;
      if (std::getenv("VERBOSE") && std::fabs(cents) > 50)
        std::fprintf(stderr, "f0 t=%.3f praat=%.1f kinemo=%.1f\n", pitch[i].t, pitch[i].v, (*frames)[i].f0_hz);
    } else if (std::getenv("VERBOSE") && pv != kv) {
      std::fprintf(stderr, "voicing t=%.3f praat=%.1f kinemo=%.1f p=%.2f\n", pitch[i].t, pitch[i].v, (*frames)[i].f0_hz, (*frames)[i].voicing_probability);
    }
  }
  int iwithin = 0;
  double max_diff = 0;
  for (size_t i = 0; i < inten.size(); ++i) {
    const double d = std::fabs((*iframes)[i].intensity_db - inten[i].v);
    iwithin += d <= 1.0;
    max_diff = std::max(max_diff, d);
  }
  std::printf(
      "{\"file\":\"%s\",\"pitch_frames\":%zu,\"voiced_both\":%d,\"f0_within_50_cents\":%.4f,"
      "\"voicing_agreement\":%.4f,\"intensity_frames\":%zu,\"intensity_within_1db\":%.4f,"
      "\"intensity_max_diff_db\":%.3f}\n",
      argv[1], pitch.size(), both, both ? static_cast<double>(within) / both : 1.0,
      pitch.empty() ? 1.0 : static_cast<double>(agree) / pitch.size(), inten.size(),
      inten.empty() ? 1.0 : static_cast<double>(iwithin) / inten.size(), max_diff);
  return 0;
}
