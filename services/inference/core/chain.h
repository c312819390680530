// Inference on a linear chain of discrete states with time-invariant
// transition weights: the shared engine of the HMM (EM), the CRF (training,
// γ, log Z) and the remapped-HMM baseline.
//
// Node terms are given as log potentials (n × S). Each step is shifted by its
// maximum before exponentiation and the forward/backward recursions are
// scaled (Rabiner's scaling), so the result equals the log-space recursion
// without its per-step log-sum-exp cost and never underflows for finite
// inputs. Transition and initial weights are given in linear space
// (probabilities for an HMM, exp(weights) for a CRF).
#pragma once

#include <vector>

#include <Eigen/Core>

namespace kinemo::inference {

using RowMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// Sets the calling thread's floating-point unit to flush denormal results
// and inputs to zero while in scope (x86 MXCSR FTZ/DAZ; a no-op elsewhere).
// Probabilities below ~1e-308 of the largest are then 0, which changes no
// reported figure, while denormal arithmetic would slow forward-backward by
// two orders of magnitude on well-separated states.
class ScopedFlushDenormals {
 public:
  ScopedFlushDenormals();
  ~ScopedFlushDenormals();
  ScopedFlushDenormals(const ScopedFlushDenormals&) = delete;
  ScopedFlushDenormals& operator=(const ScopedFlushDenormals&) = delete;

 private:
  unsigned int saved_ = 0;
};

struct ChainPosteriors {
  RowMatrix gamma;         // n × S, P(q_t = i | ·), rows sum to 1
  Eigen::MatrixXd xi_sum;  // S × S, Σ_t P(q_{t-1} = i, q_t = j | ·)
  double log_z = 0.0;      // log Σ_q Π potentials
};

// Forward pass only: log Z, and (if `alpha` is not null) the normalised
// forward beliefs α_t (n × S). Returns -inf if the chain has no support.
double ChainForward(const RowMatrix& log_node, const Eigen::MatrixXd& trans,
                    const Eigen::VectorXd& init, RowMatrix* alpha);

// Forward-backward: γ, Σ_t ξ_t (if want_xi) and log Z. Returns false if the
// chain has no support (log Z = -inf).
bool ChainForwardBackward(const RowMatrix& log_node, const Eigen::MatrixXd& trans,
                          const Eigen::VectorXd& init, bool want_xi, ChainPosteriors* out);

// Most likely state path (log-space Viterbi). `log_trans`/`log_init` are logs.
std::vector<int> ChainViterbi(const RowMatrix& log_node, const Eigen::MatrixXd& log_trans,
                              const Eigen::VectorXd& log_init);

}  // namespace kinemo::inference
