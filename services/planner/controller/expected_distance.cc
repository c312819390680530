#include "services/planner/controller/expected_distance.h"

#include <cmath>

#include <Eigen/Eigenvalues>

namespace kinemo::planner::controller {
namespace {

constexpr double kULo = -46.0, kUHi = 32.0, kStep = 0.125;
constexpr int kGrid = static_cast<int>((kUHi - kULo) / kStep) + 1;

Matrix6 SqrtPsd(const Matrix6& m) {
  Eigen::SelfAdjointEigenSolver<Matrix6> es(m);
  return es.eigenvectors() * es.eigenvalues().cwiseMax(0.0).cwiseSqrt().asDiagonal() * es.eigenvectors().transpose();
}

StatusOr<std::pair<Vector6, Matrix6>> Fit(const Eigen::MatrixXd& x, const char* field) {
  if (x.rows() < 2 || x.cols() != 6) return InvalidField(field, "needs at least 2 rows of 6 values");
  if (!x.allFinite()) return InvalidField(field, "has NaN or infinite values");
  const Vector6 mu = x.colwise().mean().transpose();
  const Eigen::MatrixXd c = x.rowwise() - mu.transpose();
  Matrix6 cov = (c.transpose() * c) / static_cast<double>(x.rows() - 1);
  if (x.rows() < 12) cov = Matrix6(cov.diagonal().asDiagonal());
  cov += 1e-3 * Matrix6::Identity();
  return std::make_pair(mu, cov);
}

}  // namespace

StatusOr<ExpectedNorm> ExpectedNorm::Create(const Vector6& mean, const Matrix6& covariance) {
  if (!mean.allFinite()) return InvalidField("mean", "has NaN or infinite values");
  if (!covariance.allFinite()) return InvalidField("covariance", "has NaN or infinite values");
  if ((covariance - covariance.transpose()).cwiseAbs().maxCoeff() > 1e-9 * (1 + covariance.cwiseAbs().maxCoeff()))
    return InvalidField("covariance", "is not symmetric");
  Eigen::SelfAdjointEigenSolver<Matrix6> es(covariance);
  if (es.eigenvalues().minCoeff() < -1e-9 * (1 + es.eigenvalues().cwiseAbs().maxCoeff()))
    return InvalidField("covariance", "is not positive semi-definite");
  ExpectedNorm n;
  n.mean_ = mean;
  n.basis_ = es.eigenvectors();
  n.lambda_ = es.eigenvalues().cwiseMax(1e-12);
  n.log_det_.resize(kGrid);
  n.weight_.resize(static_cast<size_t>(kGrid) * 6);
  for (int g = 0; g < kGrid; ++g) {
    const double t = std::exp(kULo + kStep * g);
    double ld = 0;
    for (int k = 0; k < 6; ++k) {
      ld -= 0.5 * std::log1p(2 * t * n.lambda_(k));
      n.weight_[static_cast<size_t>(g) * 6 + k] = t / (1 + 2 * t * n.lambda_(k));
    }
    n.log_det_[static_cast<size_t>(g)] = ld;
  }
  return n;
}

double ExpectedNorm::Of(const Vector6& y) const {
  const Vector6 m = basis_.transpose() * (mean_ - y);
  const Vector6 m2 = m.cwiseProduct(m);
  const double second_moment = m2.sum() + lambda_.sum();  // E‖X‖²
  double sum = 0;
  for (int g = 0; g < kGrid; ++g) {
    const double* w = &weight_[static_cast<size_t>(g) * 6];
    double log_phi = log_det_[static_cast<size_t>(g)];
    for (int k = 0; k < 6; ++k) log_phi -= w[k] * m2(k);
    const double one_minus_phi = -std::expm1(log_phi);
    const double u = kULo + kStep * g;
    const double f = one_minus_phi * std::exp(-0.5 * u);
    sum += (g == 0 || g == kGrid - 1) ? 0.5 * f : f;
  }
  double integral = sum * kStep;
  // Tails: below the grid 1 − φ ≈ t·E‖X‖², above it φ ≈ 0.
  integral += 2.0 * second_moment * std::exp(0.5 * kULo);
  integral += 2.0 * std::exp(-0.5 * kUHi);
  return integral / (2.0 * std::sqrt(M_PI));
}

StatusOr<double> ExpectedNormOf(const Vector6& m, const Matrix6& covariance) {
  KINEMO_ASSIGN_OR_RETURN(ExpectedNorm n, ExpectedNorm::Create(m, covariance));
  return n.Of(Vector6::Zero());
}

StatusOr<StyleTransform> FitStyleTransform(const Eigen::MatrixXd& neutral, const Eigen::MatrixXd& tone) {
  KINEMO_ASSIGN_OR_RETURN(auto n, Fit(neutral, "neutral"));
  KINEMO_ASSIGN_OR_RETURN(auto m, Fit(tone, "tone"));
  const Matrix6 sn = SqrtPsd(n.second);
  const Matrix6 sn_inv = sn.inverse();
  StyleTransform t;
  t.A = sn_inv * SqrtPsd(sn * m.second * sn) * sn_inv;
  t.A = 0.5 * (t.A + t.A.transpose());
  t.b = m.first - t.A * n.first;
  return t;
}

}  // namespace kinemo::planner::controller
