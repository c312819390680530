// The inference layer as one immutable object: input normaliser, prosody
// clusters, Λ_Y (Gaussian HMM on kinematics), the remapped CRF and the
// remapped-HMM baseline of Fig. 4; the training pipeline of Fig. 3; held-out
// evaluation; offline inference; and the online filter (OnlineFilter).
#pragma once

#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "common/status/status.h"
#include "services/inference/core/gaussian_hmm.h"
#include "services/inference/core/prosody_clusters.h"
#include "services/inference/core/remapped_crf.h"

namespace kinemo::inference {

inline constexpr int kKinematicDims = 6;  // T, D, V, A, C, H

// One recording: inputs x_t and kinematic parameters y_t (n × 6) on the same steps.
struct PairedSequence {
  std::string name;
  std::vector<ProsodyStep> inputs;
  Eigen::MatrixXd outputs;
};

// Checks lengths, dimensions and values; `field` prefixes messages.
Status ValidatePairedSequence(const PairedSequence& seq, std::string_view field);

struct ModelTrainParams {
  int num_states = 25;
  int window = 4;
  int num_clusters = 10;
  bool full_covariance = false;
  int hmm_restarts = 5;
  int hmm_max_iterations = 200;
  double hmm_tolerance = 1e-4;
  double crf_l2 = 1.0;
  int crf_max_iterations = 500;
  double crf_tolerance = 1e-6;
  std::uint64_t seed = 1;
  double variance_floor = 1e-3;
  int threads = 2;
};
Status ValidateTrainParams(const ModelTrainParams& p);

struct TrainReport {
  double hmm_ll_per_step = 0.0;  // log P(Y) / n under Λ_Y
  double crf_ll_per_step = 0.0;  // log P(Y | X) / n under the CRF, training data
  double train_s = 0.0;
  std::uint64_t steps = 0;
  double data_s = 0.0;  // Σ (last end_s - first start_s)
  int crf_iterations = 0;
  double hmm_s = 0.0;         // stage wall times
  double clustering_s = 0.0;
  double crf_s = 0.0;
};

// Stage ("hmm_em", "clustering", "crf_optimize", "baseline"), fraction in [0, 1]
// of the stage, message. Returning false cancels training (CANCELLED).
using TrainProgress = std::function<bool(std::string_view, double, std::string_view)>;

struct SequenceScore {
  std::uint64_t steps = 0;
  double crf_ll_per_step = 0.0;
  double hmm_ll_per_step = 0.0;
};

struct InferenceResult {
  RowMatrix smoothed;  // γ, n × S
  RowMatrix filtered;  // α, n × S (if requested)
  std::vector<int> viterbi;
};

// Brand's remapped HMM (Fig. 4 baseline): Λ_Y's initial and transition
// probabilities, with new emissions over the windowed inputs, estimated from
// Λ_Y's posteriors (remapping). The w windowed inputs are modelled as
// independent given the state (a diagonal Gaussian per state and offset,
// unvoiced F0 marginalised), which is what makes it degrade as w grows.
class RemappedHmmBaseline {
 public:
  RemappedHmmBaseline() = default;
  static StatusOr<RemappedHmmBaseline> FromParameters(int window, int num_states,
                                                      Eigen::MatrixXd means,
                                                      Eigen::MatrixXd variances);
  static RemappedHmmBaseline Fit(const std::vector<InputMatrix>& inputs,
                                 const std::vector<RowMatrix>& gammas, int window,
                                 double variance_floor);
  int window() const { return window_; }
  int num_states() const { return num_states_; }
  // Row o * S + i: state i's Gaussian for the input at offset o.
  const Eigen::MatrixXd& means() const { return means_; }
  const Eigen::MatrixXd& variances() const { return variances_; }
  RowMatrix LogObservation(const InputMatrix& m) const;  // n × S

 private:
  int window_ = 1;
  int num_states_ = 1;
  Eigen::MatrixXd means_, variances_;
};

class RemappedModel {
 public:
  RemappedModel() = default;
  static StatusOr<RemappedModel> FromParts(InputNormalizer normalizer, ProsodyClusters clusters,
                                           GaussianHmm hmm, RemappedCrf crf,
                                           RemappedHmmBaseline baseline);

  static StatusOr<RemappedModel> Train(const std::vector<PairedSequence>& data,
                                       const ModelTrainParams& params,
                                       const TrainProgress& progress, TrainReport* report);

  int num_states() const { return hmm_.num_states(); }
  int window() const { return crf_.window(); }
  int num_clusters() const { return clusters_.num_clusters(); }
  int lookahead() const { return crf_.lookahead(); }
  const InputNormalizer& normalizer() const { return normalizer_; }
  const ProsodyClusters& clusters() const { return clusters_; }
  const GaussianHmm& hmm() const { return hmm_; }
  const RemappedCrf& crf() const { return crf_; }
  const RemappedHmmBaseline& baseline() const { return baseline_; }

  // CRF observation features (n × F) of an input sequence (validated by caller).
  RowMatrix Features(std::span<const ProsodyStep> inputs) const;

  // γ (and α, Viterbi) for an input sequence. INVALID_ARGUMENT for bad input.
  StatusOr<InferenceResult> Infer(std::span<const ProsodyStep> inputs, bool filtered,
                                  bool viterbi) const;
  // Held-out log P(Y | X) per step: CRF with Λ_Y's emissions, and the baseline.
  StatusOr<SequenceScore> Evaluate(const PairedSequence& seq) const;

 private:
  InputNormalizer normalizer_;
  ProsodyClusters clusters_;
  GaussianHmm hmm_;
  RemappedCrf crf_;
  RemappedHmmBaseline baseline_;
};

// Online forward filtering: α_t after each input, one O(S² + S·F) update per
// step, all buffers allocated at construction (Push/Finish allocate
// nothing). Belief for step t is available once x_{t+lookahead} arrived.
// Not thread-safe; one per stream. The model must outlive the filter.
class OnlineFilter {
 public:
  explicit OnlineFilter(const RemappedModel& model);
  // Adds the next input (must be valid: see ValidateProsodyStep). If a belief
  // became ready, writes α into `alpha` (size S) and returns true.
  bool Push(const ProsodyStep& x, std::span<double> alpha);
  // After the last input: emits the next pending step (window truncated at
  // the end) and returns true, or false when none is left.
  bool Finish(std::span<double> alpha);
  void Reset();
  // Index of the step the next emitted belief belongs to.
  std::int64_t next_step() const { return emitted_; }

 private:
  void Emit(std::int64_t step, std::span<double> alpha);
  const RemappedModel* model_;
  int s_, k_, w_, lo_, f_;
  std::int64_t received_ = 0;  // inputs pushed
  std::int64_t emitted_ = 0;   // beliefs emitted
  Eigen::VectorXd ring_;       // w × K cluster posteriors, slot = step mod w
  Eigen::VectorXd feature_;    // F
  Eigen::VectorXd phi_;        // S
  Eigen::VectorXd alpha_;      // S
  Eigen::VectorXd tmp_;        // S
  Eigen::Vector3d x_;
};

}  // namespace kinemo::inference
