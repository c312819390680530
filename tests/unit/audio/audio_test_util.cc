#include "tests/unit/audio/audio_test_util.h"

#include <sndfile.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <fstream>
#include <iterator>
#include <limits>

#include <gtest/gtest.h>

namespace kinemo::audio::testing {

std::string SpeechPath(const std::string& name) {
  std::string path = KINEMO_TEST_DATA_DIR;
  path.append("/speech/").append(name);
  return path;
}

std::vector<std::string> LibrivoxClips() {
  std::vector<std::string> clips;
  for (const char* id : {"0870", "0880", "0890", "0920", "0930"}) {
    std::string name = "sense_and_sensibility_01_austen_64kb-";
    name.append(id).append(".wav");
    clips.push_back(SpeechPath(name));
  }
  return clips;
}

std::vector<std::uint8_t> ReadBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

TempDir::TempDir() {
  static std::atomic<int> counter{0};
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  std::filesystem::path name("kinemo_audio");
  if (info != nullptr) {
    name += "_";
    name += info->test_suite_name();
    name += "_";
    name += info->name();
  }
  name += "_";
  name += std::to_string(counter++);
  path_ = std::filesystem::path(::testing::TempDir()) / name;
  std::filesystem::remove_all(path_);
  std::filesystem::create_directories(path_);
}

TempDir::~TempDir() {
  std::error_code ec;
  std::filesystem::remove_all(path_, ec);
}

bool WriteWithSndfile(const std::string& path, std::span<const float> interleaved,
                      int sample_rate_hz, int channels, int sf_format) {
  SF_INFO info{};
  info.samplerate = sample_rate_hz;
  info.channels = channels;
  info.format = sf_format;
  if (sf_format_check(&info) == 0) return false;
  SNDFILE* file = sf_open(path.c_str(), SFM_WRITE, &info);
  if (file == nullptr) return false;
  const auto frames = static_cast<sf_count_t>(interleaved.size() / channels);
  const bool ok = sf_writef_float(file, interleaved.data(), frames) == frames;
  return sf_close(file) == 0 && ok;
}

double SnrDb(std::span<const float> ref, std::span<const float> x) {
  const std::size_t n = std::min(ref.size(), x.size());
  double signal = 0.0;
  double noise = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    signal += static_cast<double>(ref[i]) * ref[i];
    const double d = static_cast<double>(ref[i]) - x[i];
    noise += d * d;
  }
  if (noise == 0.0) return std::numeric_limits<double>::infinity();
  return 10.0 * std::log10(signal / noise);
}

double Correlation(std::span<const float> a, std::span<const float> b) {
  const std::size_t n = std::min(a.size(), b.size());
  double ma = 0.0;
  double mb = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    ma += a[i];
    mb += b[i];
  }
  ma /= static_cast<double>(n);
  mb /= static_cast<double>(n);
  double sab = 0.0;
  double saa = 0.0;
  double sbb = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    sab += (a[i] - ma) * (b[i] - mb);
    saa += (a[i] - ma) * (a[i] - ma);
    sbb += (b[i] - mb) * (b[i] - mb);
  }
  return sab / std::sqrt(saa * sbb);
}

double MaxAbsDiff(std::span<const float> a, std::span<const float> b) {
  const std::size_t n = std::min(a.size(), b.size());
  double m = 0.0;
  for (std::size_t i = 0; i < n; ++i) m = std::max(m, std::fabs(static_cast<double>(a[i]) - b[i]));
  return m;
}

std::vector<float> Interleave(const std::vector<std::vector<float>>& channels) {
  const std::size_t c = channels.size();
  const std::size_t n = channels.front().size();
  std::vector<float> out(n * c);
  for (std::size_t f = 0; f < n; ++f) {
    for (std::size_t k = 0; k < c; ++k) out[f * c + k] = channels[k][f];
  }
  return out;
}

}  // namespace kinemo::audio::testing
