// The remapped conditional random field of Gesture Controllers §6.2
// (Fig. 3b): a linear-chain CRF over the hidden states of Λ_Y, trained by
// maximum likelihood on the HMM's posterior distribution over Q (soft
// targets), from windowed cluster memberships of the prosody inputs.
//
// Features:
//   transition   1{q_{t-1}=i, q_t=j}                      weights W (S × S)
//   initial      1{q_1=i}                                  weights b (S)
//   observation  1{q_t=i} · P(x_{t+o} ∈ C_k), o ∈ window   weights U (S × F)
//                plus a bias 1{q_t=i} (last column of U)
// The window of w steps covers offsets o = -⌊w/2⌋ .. ⌈w/2⌉-1 (w = 4: t-2..t+1),
// so the CRF looks ⌈w/2⌉-1 steps ahead. Inputs outside the sequence have
// feature 0.
//
// Objective (minimised): -(1/N) Σ_seq E_{Q∼P_HMM(Q|Y)}[log P_CRF(Q|X)]
//                         + (λ / 2N) ‖θ‖², N = total steps,
// whose gradient is (model − target) expected features + λθ/N. It is the
// cross-entropy between the HMM's chain posterior and the CRF, which only
// needs the targets' γ_t and Σ_t ξ_t because W is shared over time.
#pragma once

#include <functional>
#include <vector>

#include <Eigen/Core>

#include "common/status/status.h"
#include "services/inference/core/chain.h"
#include "services/inference/core/lbfgs.h"

namespace kinemo::inference {

struct CrfTarget {
  RowMatrix features;      // n × F, from WindowFeatures()
  RowMatrix gamma;         // n × S, target P(q_t = i)
  Eigen::MatrixXd xi_sum;  // S × S, target Σ_t P(q_{t-1}=i, q_t=j)
};

struct CrfTrainParams {
  double l2 = 1.0;
  int max_iterations = 500;
  double tolerance = 1e-6;
};

class RemappedCrf {
 public:
  RemappedCrf() = default;

  static int FeatureCount(int window, int num_clusters) { return window * num_clusters + 1; }
  static int WindowLow(int window) { return -(window / 2); }
  static int Lookahead(int window) { return (window + 1) / 2 - 1; }
  // n × F observation features from n × K cluster posteriors.
  static RowMatrix WindowFeatures(const RowMatrix& cluster_posteriors, int window);

  static StatusOr<RemappedCrf> FromParameters(int window, int num_clusters,
                                              Eigen::MatrixXd transition_weights,
                                              Eigen::VectorXd initial_weights,
                                              RowMatrix observation_weights);

  // Trains from targets; `iteration` gets (iteration, objective) and may stop.
  static StatusOr<RemappedCrf> Train(const std::vector<CrfTarget>& targets, int num_states,
                                     int window, int num_clusters, const CrfTrainParams& params,
                                     const std::function<bool(int, double)>& iteration = nullptr);

  // The training objective and its gradient at a packed parameter vector
  // (W column-major, then b, then U row-major); exposed for gradient checks.
  static double Objective(const std::vector<CrfTarget>& targets, int num_states, int features,
                          double l2, const Eigen::VectorXd& theta, Eigen::VectorXd* gradient);
  Eigen::VectorXd Pack() const;

  int num_states() const { return static_cast<int>(initial_weights_.size()); }
  int window() const { return window_; }
  int num_clusters() const { return num_clusters_; }
  int lookahead() const { return Lookahead(window_); }
  const Eigen::MatrixXd& transition_weights() const { return transition_weights_; }
  const Eigen::VectorXd& initial_weights() const { return initial_weights_; }
  const RowMatrix& observation_weights() const { return observation_weights_; }
  // exp(W) and exp(b): the chain's linear-space weights.
  const Eigen::MatrixXd& exp_transition() const { return exp_transition_; }
  const Eigen::VectorXd& exp_initial() const { return exp_initial_; }

  // n × S log node potentials φ_t(i) = U_i · f_t.
  RowMatrix LogNode(const RowMatrix& features) const;
  double LogPartition(const RowMatrix& features) const;
  bool Posteriors(const RowMatrix& features, ChainPosteriors* out) const;
  RowMatrix Filtered(const RowMatrix& features) const;
  std::vector<int> Viterbi(const RowMatrix& features) const;

  // T(i, j) = exp(W_ij) / Σ_j' exp(W_ij'): the normalised transition matrix.
  Eigen::MatrixXd NormalizedTransition() const;
  // T^n by repeated squaring (n ≥ 0).
  Eigen::MatrixXd TransitionPower(int n) const;

 private:
  int window_ = 1;
  int num_clusters_ = 1;
  Eigen::MatrixXd transition_weights_;
  Eigen::VectorXd initial_weights_;
  RowMatrix observation_weights_;
  Eigen::MatrixXd exp_transition_;
  Eigen::VectorXd exp_initial_;
};

}  // namespace kinemo::inference
