#include "services/prosody/core/fft.h"

#include <cmath>
#include <numbers>

namespace kinemo::prosody {

RealFft::RealFft(std::size_t size) : n_(size), half_(size / 2) {
  bitrev_.resize(half_);
  std::size_t bits = 0;
  while ((std::size_t{1} << bits) < half_) ++bits;
  for (std::size_t i = 0; i < half_; ++i) {
    std::size_t r = 0;
    for (std::size_t b = 0; b < bits; ++b) {
      if (i & (std::size_t{1} << b)) r |= std::size_t{1} << (bits - 1 - b);
    }
    bitrev_[i] = r;
  }
  twiddle_.resize(half_ / 2);
  for (std::size_t k = 0; k < half_ / 2; ++k) {
    const double a = -2.0 * std::numbers::pi * static_cast<double>(k) / static_cast<double>(half_);
    twiddle_[k] = {static_cast<float>(std::cos(a)), static_cast<float>(std::sin(a))};
  }
  post_.resize(half_);
  for (std::size_t k = 0; k < half_; ++k) {
    const double a = -2.0 * std::numbers::pi * static_cast<double>(k) / static_cast<double>(n_);
    post_[k] = {static_cast<float>(std::cos(a)), static_cast<float>(std::sin(a))};
  }
}

void RealFft::ComplexFft(std::span<std::complex<float>> data) const {
  const std::size_t n = half_;
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t j = bitrev_[i];
    if (j > i) std::swap(data[i], data[j]);
  }
  for (std::size_t len = 2; len <= n; len <<= 1) {
    const std::size_t halflen = len >> 1;
    const std::size_t stride = n / len;
    for (std::size_t start = 0; start < n; start += len) {
      std::complex<float>* a = &data[start];
      std::complex<float>* b = a + halflen;
      for (std::size_t k = 0; k < halflen; ++k) {
        const std::complex<float> w = twiddle_[k * stride];
        // Explicit arithmetic: std::complex operator* carries NaN checks.
        const float br = b[k].real() * w.real() - b[k].imag() * w.imag();
        const float bi = b[k].real() * w.imag() + b[k].imag() * w.real();
        const float ar = a[k].real();
        const float ai = a[k].imag();
        a[k] = {ar + br, ai + bi};
        b[k] = {ar - br, ai - bi};
      }
    }
  }
}

void RealFft::Forward(std::span<const float> in, std::span<std::complex<float>> out,
                      std::span<std::complex<float>> work) const {
  for (std::size_t i = 0; i < half_; ++i) work[i] = {in[2 * i], in[2 * i + 1]};
  ComplexFft(work);
  // Split the packed transform into the spectrum of the real sequence.
  out[0] = {work[0].real() + work[0].imag(), 0.0f};
  out[half_] = {work[0].real() - work[0].imag(), 0.0f};
  for (std::size_t k = 1; k < half_; ++k) {
    const std::complex<float> z = work[k];
    const std::complex<float> zc = std::conj(work[half_ - k]);
    const float er = 0.5f * (z.real() + zc.real());
    const float ei = 0.5f * (z.imag() + zc.imag());
    // odd = (z - zc) / (2i)
    const float dr = z.real() - zc.real();
    const float di = z.imag() - zc.imag();
    const float or_ = 0.5f * di;
    const float oi = -0.5f * dr;
    const std::complex<float> w = post_[k];
    out[k] = {er + or_ * w.real() - oi * w.imag(), ei + or_ * w.imag() + oi * w.real()};
  }
}

void RealFft::Autocorrelation(std::span<const float> in, std::span<float> r,
                              std::span<std::complex<float>> spectrum,
                              std::span<std::complex<float>> work) const {
  Forward(in, spectrum, work);
  // The power spectrum P is real and even; its inverse DFT equals its
  // forward DFT divided by n. Build the full real sequence P[0..n) in `r`,
  // then transform it again.
  for (std::size_t k = 0; k <= half_; ++k) r[k] = std::norm(spectrum[k]);
  for (std::size_t k = half_ + 1; k < n_; ++k) r[k] = r[n_ - k];
  Forward(r, spectrum, work);
  const float scale = 1.0f / static_cast<float>(n_);
  for (std::size_t k = 0; k <= half_; ++k) r[k] = spectrum[k].real() * scale;
  for (std::size_t k = half_ + 1; k < n_; ++k) r[k] = r[n_ - k];
}

}  // namespace kinemo::prosody
