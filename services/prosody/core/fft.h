// A small radix-2 FFT for real sequences, planned once (twiddles and
// bit-reversal precomputed) and then run without allocating.
#pragma once

#include <complex>
#include <cstddef>
#include <span>
#include <vector>

namespace kinemo::prosody {

class RealFft {
 public:
  // `size` must be a power of two >= 8.
  explicit RealFft(std::size_t size);
  std::size_t size() const { return n_; }
  // Forward DFT of `in` (size() samples). `out` receives bins 0..size()/2
  // (size()/2 + 1 values). `work` must hold size()/2 values.
  void Forward(std::span<const float> in, std::span<std::complex<float>> out,
               std::span<std::complex<float>> work) const;
  // Autocorrelation of the zero-padded input: r[k] = sum_n in[n] in[n+k]
  // (circular over size(); pad with zeros to avoid wrap-around). `in` and
  // `r` hold size() values; `spectrum` size()/2+1, `work` size()/2.
  void Autocorrelation(std::span<const float> in, std::span<float> r,
                       std::span<std::complex<float>> spectrum,
                       std::span<std::complex<float>> work) const;

 private:
  void ComplexFft(std::span<std::complex<float>> data) const;
  std::size_t n_;
  std::size_t half_;
  std::vector<std::size_t> bitrev_;          // half_ entries
  // Twiddles of every stage, contiguous per stage (split real / imaginary).
  std::vector<float> tw_re_, tw_im_;
  std::vector<std::complex<float>> post_;  // half_ entries: exp(-2 pi i k / n_)
};

}  // namespace kinemo::prosody
