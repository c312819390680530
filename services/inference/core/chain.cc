#include "services/inference/core/chain.h"

#include <cmath>
#include <limits>

#if defined(__SSE__) || defined(__x86_64__)
#include <xmmintrin.h>
#define KINEMO_HAVE_MXCSR 1
#endif

namespace kinemo::inference {

ScopedFlushDenormals::ScopedFlushDenormals() {
#ifdef KINEMO_HAVE_MXCSR
  saved_ = _mm_getcsr();
  _mm_setcsr(saved_ | 0x8040);  // FTZ | DAZ
#endif
}
ScopedFlushDenormals::~ScopedFlushDenormals() {
#ifdef KINEMO_HAVE_MXCSR
  _mm_setcsr(saved_);
#endif
}

namespace {

// Fills e (n × S) with exp(log_node - rowmax) and shift with the row maxima.
void ShiftedExp(const RowMatrix& log_node, RowMatrix* e, Eigen::VectorXd* shift) {
  const Eigen::Index n = log_node.rows();
  *shift = log_node.rowwise().maxCoeff();
  e->resize(n, log_node.cols());
  for (Eigen::Index t = 0; t < n; ++t) {
    e->row(t) = (log_node.row(t).array() - (*shift)(t)).exp();
  }
}

// Scaled forward recursion into a (n × S) and c (n). Returns log Z.
double ScaledForward(const RowMatrix& e, const Eigen::VectorXd& shift, const Eigen::MatrixXd& trans,
                     const Eigen::VectorXd& init, RowMatrix* a, Eigen::VectorXd* c) {
  const Eigen::Index n = e.rows();
  a->resize(n, e.cols());
  c->resize(n);
  double log_z = 0.0;
  for (Eigen::Index t = 0; t < n; ++t) {
    if (t == 0) {
      a->row(0) = init.transpose().array() * e.row(0).array();
    } else {
      a->row(t).noalias() = a->row(t - 1) * trans;
      a->row(t).array() *= e.row(t).array();
    }
    const double ct = a->row(t).sum();
    if (!(ct > 0.0) || !std::isfinite(ct)) return -std::numeric_limits<double>::infinity();
    (*c)(t) = ct;
    a->row(t) /= ct;
    log_z += std::log(ct) + shift(t);
  }
  return log_z;
}

}  // namespace

double ChainForward(const RowMatrix& log_node, const Eigen::MatrixXd& trans,
                    const Eigen::VectorXd& init, RowMatrix* alpha) {
  ScopedFlushDenormals ftz;
  RowMatrix e, a_local;
  Eigen::VectorXd shift, c;
  ShiftedExp(log_node, &e, &shift);
  RowMatrix* a = alpha != nullptr ? alpha : &a_local;
  return ScaledForward(e, shift, trans, init, a, &c);
}

bool ChainForwardBackward(const RowMatrix& log_node, const Eigen::MatrixXd& trans,
                          const Eigen::VectorXd& init, bool want_xi, ChainPosteriors* out) {
  ScopedFlushDenormals ftz;
  const Eigen::Index n = log_node.rows();
  const Eigen::Index s = log_node.cols();
  RowMatrix e, a;
  Eigen::VectorXd shift, c;
  ShiftedExp(log_node, &e, &shift);
  out->log_z = ScaledForward(e, shift, trans, init, &a, &c);
  if (!std::isfinite(out->log_z)) return false;
  // Backward: b_t(i) = Σ_j T(i,j) e_{t+1}(j) b_{t+1}(j) / c_{t+1}.
  RowMatrix b(n, s);
  b.row(n - 1).setOnes();
  // eb_t = e_t ∘ b_t / c_t, kept for ξ.
  RowMatrix eb(n, s);
  eb.row(n - 1) = e.row(n - 1).array() * b.row(n - 1).array() / c(n - 1);
  for (Eigen::Index t = n - 2; t >= 0; --t) {
    b.row(t).noalias() = eb.row(t + 1) * trans.transpose();
    eb.row(t) = e.row(t).array() * b.row(t).array() / c(t);
  }
  out->gamma = a.array() * b.array();
  if (want_xi) {
    if (n > 1) {
      Eigen::MatrixXd r = a.topRows(n - 1).transpose() * eb.bottomRows(n - 1);
      out->xi_sum = trans.array() * r.array();
    } else {
      out->xi_sum = Eigen::MatrixXd::Zero(s, s);
    }
  }
  return true;
}

std::vector<int> ChainViterbi(const RowMatrix& log_node, const Eigen::MatrixXd& log_trans,
                              const Eigen::VectorXd& log_init) {
  const Eigen::Index n = log_node.rows();
  const Eigen::Index s = log_node.cols();
  std::vector<int> path(n);
  if (n == 0) return path;
  Eigen::MatrixXi back(n, s);
  Eigen::VectorXd delta = log_init + log_node.row(0).transpose();
  Eigen::VectorXd next(s);
  for (Eigen::Index t = 1; t < n; ++t) {
    for (Eigen::Index j = 0; j < s; ++j) {
      Eigen::Index arg;
      next(j) = (delta + log_trans.col(j)).maxCoeff(&arg) + log_node(t, j);
      back(t, j) = static_cast<int>(arg);
    }
    delta.swap(next);
  }
  Eigen::Index last;
  delta.maxCoeff(&last);
  path[n - 1] = static_cast<int>(last);
  for (Eigen::Index t = n - 1; t > 0; --t) path[t - 1] = back(t, path[t]);
  return path;
}

}  // namespace kinemo::inference
