// Prosody inputs x_t = (F̄0, Ī, L) (Gesture Controllers §5.2) and their
// Gaussian clusters C_1..C_K found by EM (§6.2).
//
// Inputs are mapped to a working space: F0 in semitones re 100 Hz,
// intensity in dB, log length; each standardised with the training data's
// mean and deviation (InputNormalizer). F0 is undefined on unvoiced steps;
// the paper represents it there as a uniformly distributed variable. With
// diagonal clusters a uniform F0 density is the same constant factor for
// every cluster, so it cancels in P(x_t ∈ C_k): we marginalise it, i.e. the
// unvoiced steps' responsibilities and log-densities use only (I, L), and
// they do not contribute to the F0 statistics in the M-step.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "common/status/status.h"
#include "services/inference/core/chain.h"

namespace kinemo::inference {

// One time step of prosody input (one syllable).
struct ProsodyStep {
  double start_s = 0.0;
  double end_s = 0.0;
  double f0_mean_hz = 0.0;  // ignored when !voiced
  double intensity_mean_db = 0.0;
  double length_s = 0.0;
  bool voiced = false;
};

inline constexpr int kInputDims = 3;

// Bounds of a step's values: far outside any speech, but inside what the
// models compute with (a value like 1e308 overflows their features).
inline constexpr double kMaxStepTimeS = 86400.0;      // start_s, end_s in [0, a day]
inline constexpr double kMaxStepF0Hz = 5000.0;        // f0_mean_hz in (0, 5000] when voiced
inline constexpr double kMinStepIntensityDb = -200.0;  // intensity_mean_db in [-200, 200]
inline constexpr double kMaxStepIntensityDb = 200.0;
inline constexpr double kMaxStepLengthS = 60.0;  // length_s in (0, 60]

// Checks values (finite and within the bounds above, end not before start).
// `field` prefixes messages, e.g. "inputs[12]".
Status ValidateProsodyStep(const ProsodyStep& x, std::string_view field);
Status ValidateProsodySequence(std::span<const ProsodyStep> xs, std::string_view field);

// Raw working-space vector (semitones, dB, log s).
Eigen::Vector3d RawInput(const ProsodyStep& x);

struct InputNormalizer {
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  Eigen::Vector3d scale = Eigen::Vector3d::Ones();
  static InputNormalizer Fit(const std::vector<std::vector<ProsodyStep>>& sequences);
  // Normalised vector; the F0 entry is meaningless when !x.voiced.
  Eigen::Vector3d Apply(const ProsodyStep& x) const {
    return (RawInput(x) - mean).cwiseQuotient(scale);
  }
};

// Normalised inputs of one sequence: values (n × 3) and voiced flags.
struct InputMatrix {
  Eigen::MatrixXd x;
  std::vector<unsigned char> voiced;
};
InputMatrix MakeInputMatrix(const InputNormalizer& norm, std::span<const ProsodyStep> xs);

// K diagonal Gaussian clusters over the normalised inputs.
class ProsodyClusters {
 public:
  struct TrainParams {
    int num_clusters = 10;
    int max_iterations = 200;
    double tolerance = 1e-6;
    double variance_floor = 1e-3;
    std::uint64_t seed = 1;
  };
  ProsodyClusters() = default;
  static StatusOr<ProsodyClusters> FromParameters(Eigen::VectorXd weights, Eigen::MatrixXd means,
                                                  Eigen::MatrixXd variances);
  static StatusOr<ProsodyClusters> Train(const std::vector<InputMatrix>& data,
                                         const TrainParams& params);

  int num_clusters() const { return static_cast<int>(weights_.size()); }
  const Eigen::VectorXd& weights() const { return weights_; }
  const Eigen::MatrixXd& means() const { return means_; }          // K × 3
  const Eigen::MatrixXd& variances() const { return variances_; }  // K × 3

  // P(x ∈ C_k) for k = 0..K-1 into `out` (size K). No allocation.
  void Posterior(const double* x, bool voiced, double* out) const;
  // n × K posteriors of a sequence.
  RowMatrix Posteriors(const InputMatrix& m) const;
  // Mean log-density per step (voiced F0 included, unvoiced marginalised).
  double LogLikelihoodPerStep(const std::vector<InputMatrix>& data) const;

 private:
  void Prepare();
  Eigen::VectorXd weights_;
  Eigen::MatrixXd means_, variances_;
  // Precomputed: log w_k - 0.5 Σ_d log(2π σ²) split per dimension.
  Eigen::MatrixXd log_norm_dim_;  // K × 3: -0.5 log(2π σ²_kd)
  Eigen::VectorXd log_weight_;
  Eigen::MatrixXd inv_var_;  // K × 3
};

}  // namespace kinemo::inference
