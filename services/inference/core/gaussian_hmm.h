// Gaussian hidden Markov model Λ_Y over kinematic parameters (Gesture
// Controllers §6.2, Fig. 3a): diagonal or full covariance emissions,
// k-means++ initialisation, EM with scaled (log-shifted) recursions, several
// restarts (in parallel), convergence on the log-likelihood per step, and
// variance floors relative to the data's variance.
#pragma once

#include <cstdint>
#include <functional>
#include <random>
#include <vector>

#include <Eigen/Core>

#include "common/status/status.h"
#include "services/inference/core/chain.h"

namespace kinemo::inference {

struct HmmTrainParams {
  int num_states = 25;
  bool full_covariance = false;
  int restarts = 5;
  int max_iterations = 200;
  double tolerance = 1e-4;      // on the log-likelihood per step
  double variance_floor = 1e-3;  // relative to the data's per-dimension variance
  std::uint64_t seed = 1;
  int threads = 2;
};

// Called after each EM iteration: (restart, iteration, log-likelihood per step).
using HmmProgress = std::function<void(int, int, double)>;

// A trained HMM. Immutable after training; safe to read from many threads.
class GaussianHmm {
 public:
  GaussianHmm() = default;
  // Builds from parameters (e.g. loaded from a file). Validates shapes,
  // stochastic rows and positive-definite covariances.
  static StatusOr<GaussianHmm> FromParameters(Eigen::VectorXd initial, Eigen::MatrixXd transition,
                                              Eigen::MatrixXd means,
                                              std::vector<Eigen::MatrixXd> covariances,
                                              bool full_covariance);

  // EM on `sequences` (each n_i × D). Best of params.restarts.
  static StatusOr<GaussianHmm> Train(const std::vector<Eigen::MatrixXd>& sequences,
                                     const HmmTrainParams& params,
                                     const HmmProgress& progress = nullptr);

  int num_states() const { return static_cast<int>(initial_.size()); }
  int dims() const { return static_cast<int>(means_.cols()); }
  bool full_covariance() const { return full_; }
  const Eigen::VectorXd& initial() const { return initial_; }
  const Eigen::MatrixXd& transition() const { return transition_; }
  const Eigen::MatrixXd& means() const { return means_; }  // S × D
  const std::vector<Eigen::MatrixXd>& covariances() const { return covariances_; }

  // log N(y_t; μ_i, Σ_i), n × S.
  RowMatrix LogEmissions(const Eigen::MatrixXd& y) const;
  // log P(Y) of one sequence.
  double LogLikelihood(const Eigen::MatrixXd& y) const;
  // γ and Σξ for one sequence (false if it has no support).
  bool Posteriors(const Eigen::MatrixXd& y, ChainPosteriors* out) const;
  // Draws a state path and outputs (for planted-structure tests).
  void Sample(int n, std::mt19937_64& rng, std::vector<int>* states, Eigen::MatrixXd* y) const;

 private:
  void Prepare();  // Cholesky factors and log-normalisers
  Eigen::VectorXd initial_;
  Eigen::MatrixXd transition_;
  Eigen::MatrixXd means_;
  std::vector<Eigen::MatrixXd> covariances_;
  bool full_ = false;
  std::vector<Eigen::MatrixXd> chol_;  // lower Cholesky factors
  Eigen::VectorXd log_norm_;           // -0.5 (D log 2π + log|Σ|)
};

// k-means++ seeding followed by a few Lloyd iterations; returns k × D centres
// and the assignment of each row of `x`.
Eigen::MatrixXd KMeansPlusPlus(const Eigen::MatrixXd& x, int k, int lloyd_iterations,
                               std::mt19937_64& rng, std::vector<int>* assignment);

}  // namespace kinemo::inference
