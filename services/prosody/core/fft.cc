#include "services/prosody/core/fft.h"

#include <algorithm>
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
  for (std::size_t len = 2; len <= half_; len <<= 1) {
    for (std::size_t k = 0; k < len / 2; ++k) {
      const double a = -2.0 * std::numbers::pi * static_cast<double>(k) / static_cast<double>(len);
      tw_re_.push_back(static_cast<float>(std::cos(a)));
      tw_im_.push_back(static_cast<float>(std::sin(a)));
    }
  }
  post_.resize(half_);
  for (std::size_t k = 0; k < half_; ++k) {
    const double a = -2.0 * std::numbers::pi * static_cast<double>(k) / static_cast<double>(n_);
    post_[k] = {static_cast<float>(std::cos(a)), static_cast<float>(std::sin(a))};
  }
}

void RealFft::ComplexFft(std::span<std::complex<float>> data) const {
  const std::size_t n = half_;
  // std::complex<float> is layout-compatible with float[2].
  float* d = reinterpret_cast<float*>(data.data());
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t j = bitrev_[i];
    if (j > i) {
      std::swap(d[2 * i], d[2 * j]);
      std::swap(d[2 * i + 1], d[2 * j + 1]);
    }
  }
  // Stages 1 and 2 (twiddles 1 and -i) in one pass.
  for (std::size_t q = 0; q < n; q += 4) {
    float* x = d + 2 * q;
    const float a0r = x[0] + x[2], a0i = x[1] + x[3];
    const float a1r = x[0] - x[2], a1i = x[1] - x[3];
    const float b0r = x[4] + x[6], b0i = x[5] + x[7];
    const float b1r = x[4] - x[6], b1i = x[5] - x[7];
    x[0] = a0r + b0r;
    x[1] = a0i + b0i;
    x[4] = a0r - b0r;
    x[5] = a0i - b0i;
    // b1 * (-i) = (b1i, -b1r)
    x[2] = a1r + b1i;
    x[3] = a1i - b1r;
    x[6] = a1r - b1i;
    x[7] = a1i + b1r;
  }
  std::size_t tw = 1 + 2;  // twiddles of the stages done above
  for (std::size_t len = 8; len <= n; len <<= 1) {
    const std::size_t halflen = len >> 1;
    const float* wr = &tw_re_[tw];
    const float* wi = &tw_im_[tw];
    for (std::size_t start = 0; start < n; start += len) {
      float* a = d + 2 * start;
      float* b = a + 2 * halflen;
      for (std::size_t k = 0; k < halflen; ++k) {
        const float xr = b[2 * k], xi = b[2 * k + 1];
        const float br = xr * wr[k] - xi * wi[k];
        const float bi = xr * wi[k] + xi * wr[k];
        const float ar = a[2 * k], ai = a[2 * k + 1];
        a[2 * k] = ar + br;
        a[2 * k + 1] = ai + bi;
        b[2 * k] = ar - br;
        b[2 * k + 1] = ai - bi;
      }
    }
    tw += halflen;
  }
}

void RealFft::Forward(std::span<const float> in, std::span<std::complex<float>> out,
                      std::span<std::complex<float>> work) const {
  float* w = reinterpret_cast<float*>(work.data());
  std::copy(in.begin(), in.begin() + n_, w);  // even samples -> re, odd -> im
  ComplexFft(work);
  float* o = reinterpret_cast<float*>(out.data());
  const float* p = reinterpret_cast<const float*>(post_.data());
  // Split the packed transform into the spectrum of the real sequence.
  o[0] = w[0] + w[1];
  o[1] = 0.0f;
  o[2 * half_] = w[0] - w[1];
  o[2 * half_ + 1] = 0.0f;
  for (std::size_t k = 1; k < half_; ++k) {
    const float zr = w[2 * k], zi = w[2 * k + 1];
    const float cr = w[2 * (half_ - k)], ci = -w[2 * (half_ - k) + 1];  // conj(z[half - k])
    const float er = 0.5f * (zr + cr), ei = 0.5f * (zi + ci);
    // odd = (z - conj) / (2i)
    const float odr = 0.5f * (zi - ci), odi = -0.5f * (zr - cr);
    const float tr = p[2 * k], ti = p[2 * k + 1];
    o[2 * k] = er + odr * tr - odi * ti;
    o[2 * k + 1] = ei + odr * ti + odi * tr;
  }
}

void RealFft::Autocorrelation(std::span<const float> in, std::span<float> r,
                              std::span<std::complex<float>> spectrum,
                              std::span<std::complex<float>> work) const {
  Forward(in, spectrum, work);
  // The power spectrum P is real and even; its inverse DFT equals its
  // forward DFT divided by n. Build the full real sequence P[0..n) in `r`,
  // then transform it again.
  const float* sp = reinterpret_cast<const float*>(spectrum.data());
  for (std::size_t k = 0; k <= half_; ++k) r[k] = sp[2 * k] * sp[2 * k] + sp[2 * k + 1] * sp[2 * k + 1];
  for (std::size_t k = half_ + 1; k < n_; ++k) r[k] = r[n_ - k];
  Forward(r, spectrum, work);
  const float scale = 1.0f / static_cast<float>(n_);
  for (std::size_t k = 0; k <= half_; ++k) r[k] = sp[2 * k] * scale;
  for (std::size_t k = half_ + 1; k < n_; ++k) r[k] = r[n_ - k];
}

}  // namespace kinemo::prosody
