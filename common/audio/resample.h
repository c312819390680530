// Sample-rate conversion with libsoxr: whole buffers and live streams.
//
// Both paths use the same soxr configuration (single-threaded, linear phase,
// quality per ResampleQuality), so a stream fed in chunks of any size and
// flushed produces the same samples as Resample() on the whole buffer (up to
// float rounding; tested). soxr compensates its filter delay: output sample
// k is at time k / out_rate_hz, aligned with the input.
//
// Output length: Resample() returns round(n · out / in) samples for n input
// samples; a stream returns the same total after Flush().
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "common/audio/audio.h"
#include "common/status/status.h"

namespace kinemo::audio {

enum class ResampleQuality {
  kMedium,    // soxr MQ: 16-bit, medium rolloff (fast)
  kHigh,      // soxr HQ: 20-bit (default)
  kVeryHigh,  // soxr VHQ: 28-bit
};

struct ResampleOptions {
  ResampleQuality quality = ResampleQuality::kHigh;
};

// Resamples a whole mono buffer. Equal rates return a copy.
// Errors: INVALID_ARGUMENT for rates <= 0 or above 10 MHz.
StatusOr<std::vector<float>> Resample(std::span<const float> samples,
                                      int in_rate_hz, int out_rate_hz,
                                      const ResampleOptions& options = {});

// Resamples decoded audio to `rate_hz` (samples, sample_rate_hz and
// duration_s updated; the rest kept).
StatusOr<DecodedAudio> ToAnalysisRate(DecodedAudio audio, int rate_hz,
                                      const ResampleOptions& options = {});

// A live resampler: feed mono chunks of any size (including 0), collect the
// output, and Flush() at the end of the stream. Move-only; one stream per
// object; not thread-safe (one producer).
class StreamingResampler {
 public:
  static StatusOr<StreamingResampler> Create(int in_rate_hz, int out_rate_hz,
                                             const ResampleOptions& options = {});

  StreamingResampler(StreamingResampler&&) noexcept;
  StreamingResampler& operator=(StreamingResampler&&) noexcept;
  ~StreamingResampler();

  // Appends the output available so far to `out`. Allocates only when `out`
  // must grow. FAILED_PRECONDITION after Flush() (until Reset()).
  Status Process(std::span<const float> in, std::vector<float>& out);

  // Ends the stream: appends the remaining output (the filter's tail).
  Status Flush(std::vector<float>& out);

  // Starts a new stream with the same rates.
  Status Reset();

  int in_rate_hz() const { return in_rate_hz_; }
  int out_rate_hz() const { return out_rate_hz_; }
  int64_t input_frames() const { return input_frames_; }
  int64_t output_frames() const { return output_frames_; }

  // Output samples owed for the input already given (the algorithmic latency
  // of the filter, in output samples; 0 for equal rates).
  int64_t pending_output_frames() const;

 private:
  struct Impl;
  explicit StreamingResampler(std::unique_ptr<Impl> impl, int in_rate_hz,
                              int out_rate_hz);
  Status Drain(const float* in, std::size_t n, std::vector<float>& out);

  std::unique_ptr<Impl> impl_;
  int in_rate_hz_ = 0;
  int out_rate_hz_ = 0;
  int64_t input_frames_ = 0;
  int64_t output_frames_ = 0;
  bool flushed_ = false;
};

}  // namespace kinemo::audio
