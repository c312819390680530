// δ = E‖Y − y‖ by quadrature against closed forms and Monte Carlo; style
// transforms map the neutral Gaussian onto the tone's.
#include "services/planner/controller/expected_distance.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include <Eigen/Cholesky>

namespace kinemo::planner::controller {
namespace {

Matrix6 RandomCovariance(std::mt19937_64& rng, double scale) {
  std::normal_distribution<double> n(0, 1);
  Matrix6 a;
  for (int i = 0; i < 36; ++i) a(i / 6, i % 6) = n(rng);
  return scale * (a * a.transpose() / 6.0 + 0.05 * Matrix6::Identity());
}

TEST(ExpectedNorm, OneDimensionalClosedForm) {
  // Only the first coordinate varies: E|X| for X ~ N(m, s²) is
  // s·sqrt(2/π)·exp(−m²/2s²) + m·(1 − 2Φ(−m/s)).
  for (double m : {0.0, 0.3, 1.0, 4.0}) {
    for (double s : {0.1, 1.0, 2.5}) {
      Vector6 mean = Vector6::Zero();
      mean(0) = m;
      Matrix6 cov = Matrix6::Zero();
      cov(0, 0) = s * s;
      auto got = ExpectedNormOf(mean, cov);
      ASSERT_TRUE(got.ok()) << got.status();
      const double phi = 0.5 * std::erfc(m / s / std::sqrt(2.0));
      const double want = s * std::sqrt(2 / M_PI) * std::exp(-m * m / (2 * s * s)) + m * (1 - 2 * phi);
      EXPECT_NEAR(*got, want, 1e-9 * (1 + want)) << "m=" << m << " s=" << s;
    }
  }
}

TEST(ExpectedNorm, IsotropicCentralClosedForm) {
  // ‖X‖/σ is chi with 6 degrees of freedom: mean √2·Γ(3.5)/Γ(3).
  for (double s : {0.01, 0.7, 30.0}) {
    auto got = ExpectedNormOf(Vector6::Zero(), s * s * Matrix6::Identity());
    ASSERT_TRUE(got.ok());
    const double want = s * std::sqrt(2.0) * std::tgamma(3.5) / std::tgamma(3.0);
    EXPECT_NEAR(*got, want, 1e-9 * want);
  }
}

TEST(ExpectedNorm, FullCovarianceMatchesMonteCarlo) {
  std::mt19937_64 rng(7);
  std::normal_distribution<double> n(0, 1);
  for (int trial = 0; trial < 4; ++trial) {
    const Matrix6 cov = RandomCovariance(rng, trial + 0.5);
    Vector6 mean;
    for (int k = 0; k < 6; ++k) mean(k) = 1.5 * n(rng);
    auto norm = ExpectedNorm::Create(mean, cov);
    ASSERT_TRUE(norm.ok());
    Vector6 y;
    for (int k = 0; k < 6; ++k) y(k) = n(rng);
    const double got = norm->Of(y);
    const Matrix6 l = cov.llt().matrixL();
    const int samples = 400000;
    double sum = 0, sum2 = 0;
    for (int s = 0; s < samples; ++s) {
      Vector6 z;
      for (int k = 0; k < 6; ++k) z(k) = n(rng);
      const double d = (mean + l * z - y).norm();
      sum += d;
      sum2 += d * d;
    }
    const double mc = sum / samples;
    const double se = std::sqrt((sum2 / samples - mc * mc) / samples);
    EXPECT_NEAR(got, mc, 4 * se) << "trial " << trial;
  }
}

TEST(ExpectedNorm, RejectsBadCovariance) {
  Matrix6 cov = Matrix6::Identity();
  cov(0, 0) = -1;
  EXPECT_EQ(ExpectedNorm::Create(Vector6::Zero(), cov).status().code(), absl::StatusCode::kInvalidArgument);
  cov = Matrix6::Identity();
  cov(0, 1) = 0.5;  // not symmetric
  EXPECT_EQ(ExpectedNorm::Create(Vector6::Zero(), cov).status().code(), absl::StatusCode::kInvalidArgument);
  Vector6 m = Vector6::Zero();
  m(2) = std::nan("");
  auto st = ExpectedNorm::Create(m, Matrix6::Identity()).status();
  EXPECT_EQ(st.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(st.message().find("mean"), std::string::npos);
}

TEST(StyleTransform, MapsNeutralGaussianOntoTone) {
  std::mt19937_64 rng(3);
  std::normal_distribution<double> n(0, 1);
  const Matrix6 cn = RandomCovariance(rng, 1.0), cm = RandomCovariance(rng, 2.0);
  const Matrix6 ln = cn.llt().matrixL(), lm = cm.llt().matrixL();
  Vector6 mn, mm;
  for (int k = 0; k < 6; ++k) {
    mn(k) = n(rng);
    mm(k) = n(rng) + 1;
  }
  Eigen::MatrixXd a(3000, 6), b(3000, 6);
  for (int r = 0; r < 3000; ++r) {
    Vector6 z1, z2;
    for (int k = 0; k < 6; ++k) {
      z1(k) = n(rng);
      z2(k) = n(rng);
    }
    a.row(r) = (mn + ln * z1).transpose();
    b.row(r) = (mm + lm * z2).transpose();
  }
  auto t = FitStyleTransform(a, b);
  ASSERT_TRUE(t.ok()) << t.status();
  // The transformed neutral sample has the tone sample's mean and covariance.
  Eigen::MatrixXd ta = (a * t->A.transpose()).rowwise() + t->b.transpose();
  const Vector6 mu_t = ta.colwise().mean().transpose(), mu_b = b.colwise().mean().transpose();
  EXPECT_LT((mu_t - mu_b).norm(), 1e-9);
  const Eigen::MatrixXd ca = ta.rowwise() - mu_t.transpose(), cb = b.rowwise() - mu_b.transpose();
  const Matrix6 cov_t = ca.transpose() * ca / 2999.0, cov_b = cb.transpose() * cb / 2999.0;
  // Exactly, for the fitted Gaussians (which carry a 1e-3 ridge).
  const Eigen::MatrixXd c0 = a.rowwise() - a.colwise().mean();
  const Matrix6 cov_a = c0.transpose() * c0 / 2999.0 + 1e-3 * Matrix6::Identity();
  const Matrix6 mapped = t->A * cov_a * t->A.transpose();
  EXPECT_LT((mapped - (cov_b + 1e-3 * Matrix6::Identity())).norm() / cov_b.norm(), 1e-9);
  (void)cov_t;
  EXPECT_LT((t->A - t->A.transpose()).norm(), 1e-9);  // symmetric (optimal transport)
  EXPECT_EQ(FitStyleTransform(a.topRows(1), b).status().code(), absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace kinemo::planner::controller
