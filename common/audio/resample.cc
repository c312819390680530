#include "common/audio/resample.h"

#include <soxr.h>

#include <algorithm>
#include <cmath>
#include <utility>

#include "absl/strings/str_cat.h"

namespace kinemo::audio {
namespace {

constexpr int kMaxRateHz = 10'000'000;
// Output is produced into `out` in steps of at most this many samples.
constexpr std::size_t kOutputStep = 8192;

Status CheckRate(std::string_view field, int rate_hz) {
  if (rate_hz <= 0 || rate_hz > kMaxRateHz) {
    return InvalidField(field, rate_hz, " is not a valid rate (1..", kMaxRateHz, " Hz)");
  }
  return absl::OkStatus();
}

unsigned long Recipe(ResampleQuality quality) {
  switch (quality) {
    case ResampleQuality::kMedium: return SOXR_MQ;
    case ResampleQuality::kHigh: return SOXR_HQ;
    case ResampleQuality::kVeryHigh: return SOXR_VHQ;
  }
  return SOXR_HQ;
}

}  // namespace

struct StreamingResampler::Impl {
  soxr_t soxr = nullptr;  // null when the rates are equal (pass-through)
  ~Impl() {
    if (soxr != nullptr) soxr_delete(soxr);
  }
};

StreamingResampler::StreamingResampler(std::unique_ptr<Impl> impl, int in_rate_hz,
                                       int out_rate_hz)
    : impl_(std::move(impl)), in_rate_hz_(in_rate_hz), out_rate_hz_(out_rate_hz) {}
StreamingResampler::StreamingResampler(StreamingResampler&&) noexcept = default;
StreamingResampler& StreamingResampler::operator=(StreamingResampler&&) noexcept = default;
StreamingResampler::~StreamingResampler() = default;

StatusOr<StreamingResampler> StreamingResampler::Create(int in_rate_hz, int out_rate_hz,
                                                        const ResampleOptions& options) {
  KINEMO_RETURN_IF_ERROR(CheckRate("resample.in_rate_hz", in_rate_hz));
  KINEMO_RETURN_IF_ERROR(CheckRate("resample.out_rate_hz", out_rate_hz));
  auto impl = std::make_unique<Impl>();
  if (in_rate_hz != out_rate_hz) {
    const soxr_io_spec_t io = soxr_io_spec(SOXR_FLOAT32_I, SOXR_FLOAT32_I);
    const soxr_quality_spec_t quality = soxr_quality_spec(Recipe(options.quality), 0);
    const soxr_runtime_spec_t runtime = soxr_runtime_spec(1);  // one thread, deterministic
    soxr_error_t error = nullptr;
    impl->soxr = soxr_create(in_rate_hz, out_rate_hz, 1, &error, &io, &quality, &runtime);
    if (error != nullptr || impl->soxr == nullptr) {
      return absl::InternalError(kinemo::StrCat("resample: soxr_create(", in_rate_hz, " -> ",
                                              out_rate_hz, " Hz) failed: ", soxr_strerror(error)));
    }
  }
  return StreamingResampler(std::move(impl), in_rate_hz, out_rate_hz);
}

// Feeds `n` samples (in == nullptr: end of input) and appends all output.
Status StreamingResampler::Drain(const float* in, std::size_t n, std::vector<float>& out) {
  std::size_t consumed = 0;
  while (true) {
    const std::size_t old_size = out.size();
    // Enough room for this input's share plus a step for buffered output.
    const std::size_t remaining = n - consumed;
    const std::size_t room =
        static_cast<std::size_t>(std::ceil(static_cast<double>(remaining) * out_rate_hz_ /
                                           in_rate_hz_)) +
        kOutputStep;
    out.resize(old_size + room);
    std::size_t idone = 0;
    std::size_t odone = 0;
    const soxr_error_t error =
        soxr_process(impl_->soxr, in == nullptr ? nullptr : in + consumed, remaining, &idone,
                     out.data() + old_size, room, &odone);
    out.resize(old_size + odone);
    output_frames_ += static_cast<int64_t>(odone);
    if (error != nullptr) {
      return absl::InternalError(kinemo::StrCat("resample: soxr_process failed: ", error));
    }
    if (idone == 0 && odone == 0 && consumed < n) {
      return absl::InternalError(kinemo::StrCat("resample: soxr made no progress with ",
                                              n - consumed, " input samples left"));
    }
    consumed += idone;
    // Done when all input is taken and soxr had spare output room (so it
    // holds nothing more it could give for this input).
    if (consumed >= n && odone < room) break;
  }
  return absl::OkStatus();
}

Status StreamingResampler::Process(std::span<const float> in, std::vector<float>& out) {
  if (flushed_) {
    return absl::FailedPreconditionError(
        "resample: Process() after Flush(); call Reset() to start a new stream");
  }
  input_frames_ += static_cast<int64_t>(in.size());
  if (impl_->soxr == nullptr) {
    out.insert(out.end(), in.begin(), in.end());
    output_frames_ += static_cast<int64_t>(in.size());
    return absl::OkStatus();
  }
  if (in.empty()) return absl::OkStatus();
  return Drain(in.data(), in.size(), out);
}

Status StreamingResampler::Flush(std::vector<float>& out) {
  if (flushed_) return absl::OkStatus();
  flushed_ = true;
  if (impl_->soxr == nullptr) return absl::OkStatus();
  return Drain(nullptr, 0, out);
}

Status StreamingResampler::Reset() {
  flushed_ = false;
  input_frames_ = 0;
  output_frames_ = 0;
  if (impl_->soxr != nullptr) {
    const soxr_error_t error = soxr_clear(impl_->soxr);
    if (error != nullptr) {
      return absl::InternalError(kinemo::StrCat("resample: soxr_clear failed: ", error));
    }
  }
  return absl::OkStatus();
}

int64_t StreamingResampler::pending_output_frames() const {
  if (impl_->soxr == nullptr) return 0;
  return static_cast<int64_t>(std::llround(soxr_delay(impl_->soxr)));
}

StatusOr<std::vector<float>> Resample(std::span<const float> samples, int in_rate_hz,
                                      int out_rate_hz, const ResampleOptions& options) {
  KINEMO_ASSIGN_OR_RETURN(auto resampler,
                          StreamingResampler::Create(in_rate_hz, out_rate_hz, options));
  std::vector<float> out;
  out.reserve(static_cast<std::size_t>(
                  std::ceil(static_cast<double>(samples.size()) * out_rate_hz / in_rate_hz)) +
              kOutputStep);
  KINEMO_RETURN_IF_ERROR(resampler.Process(samples, out));
  KINEMO_RETURN_IF_ERROR(resampler.Flush(out));
  return out;
}

StatusOr<DecodedAudio> ToAnalysisRate(DecodedAudio audio, int rate_hz,
                                      const ResampleOptions& options) {
  KINEMO_RETURN_IF_ERROR(CheckRate("resample.out_rate_hz", rate_hz));
  if (audio.sample_rate_hz == rate_hz) return audio;
  KINEMO_ASSIGN_OR_RETURN(audio.samples,
                          Resample(audio.samples, audio.sample_rate_hz, rate_hz, options));
  audio.sample_rate_hz = rate_hz;
  audio.duration_s = static_cast<double>(audio.samples.size()) / rate_hz;
  return audio;
}

}  // namespace kinemo::audio
