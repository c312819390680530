// Helpers for the audio tests: real clips, temp files, signal comparisons.
#pragma once

#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

namespace kinemo::audio::testing {

// Path of a file under tests/data/speech.
std::string SpeechPath(const std::string& name);

// The five LibriVox clips (16 kHz, 16-bit, mono).
std::vector<std::string> LibrivoxClips();

std::vector<std::uint8_t> ReadBytes(const std::string& path);

// A fresh directory under the test temp dir, removed by the destructor.
class TempDir {
 public:
  TempDir();
  ~TempDir();
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  std::string File(const std::string& name) const { return (path_ / name).string(); }

 private:
  std::filesystem::path path_;
};

// Writes interleaved samples with libsndfile directly (any major|subtype),
// for containers kinemo_audio does not write (FLAC, OGG, AU, ...). Returns
// false if this libsndfile cannot write that format.
bool WriteWithSndfile(const std::string& path, std::span<const float> interleaved,
                      int sample_rate_hz, int channels, int sf_format);

// 10·log10(Σref² / Σ(ref−x)²) over the common length; +inf when identical.
double SnrDb(std::span<const float> ref, std::span<const float> x);
// Pearson correlation over the common length.
double Correlation(std::span<const float> a, std::span<const float> b);
double MaxAbsDiff(std::span<const float> a, std::span<const float> b);

// Interleaves channels (all the same length).
std::vector<float> Interleave(const std::vector<std::vector<float>>& channels);

}  // namespace kinemo::audio::testing
