#include "services/inference/core/gaussian_hmm.h"

#include <random>

#include <gtest/gtest.h>

#include "tests/unit/inference/test_util.h"

namespace kinemo::inference {
namespace {

GaussianHmm PlantedHmm(int s, bool full, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> nd;
  const int d = 6;
  Eigen::VectorXd init = Eigen::VectorXd::Constant(s, 1.0 / s);
  Eigen::MatrixXd tr = Eigen::MatrixXd::Constant(s, s, 0.2 / (s - 1));
  tr.diagonal().setConstant(0.8);
  Eigen::MatrixXd means(s, d);
  for (int i = 0; i < s; ++i)
    for (int k = 0; k < d; ++k) means(i, k) = 2.5 * nd(rng);
  std::vector<Eigen::MatrixXd> covs(s);
  for (int i = 0; i < s; ++i) {
    Eigen::MatrixXd a = Eigen::MatrixXd::Zero(d, d);
    for (int r = 0; r < d; ++r)
      for (int c = 0; c < d; ++c) a(r, c) = (full || r == c) ? 0.4 * nd(rng) : 0.0;
    covs[i] = a * a.transpose() + 0.2 * Eigen::MatrixXd::Identity(d, d);
    if (!full) covs[i] = Eigen::MatrixXd(covs[i].diagonal().asDiagonal());
  }
  return *GaussianHmm::FromParameters(init, tr, means, covs, full);
}

void CheckRecovery(bool full) {
  const int s = 4;
  const GaussianHmm truth = PlantedHmm(s, full, full ? 11 : 7);
  std::mt19937_64 rng(42);
  std::vector<Eigen::MatrixXd> train;
  for (int k = 0; k < 4; ++k) {
    std::vector<int> q;
    Eigen::MatrixXd y;
    truth.Sample(500, rng, &q, &y);
    train.push_back(y);
  }
  HmmTrainParams p;
  p.num_states = s;
  p.full_covariance = full;
  p.restarts = 3;
  auto learned = GaussianHmm::Train(train, p);
  ASSERT_TRUE(learned.ok()) << learned.status();
  std::vector<int> q;
  Eigen::MatrixXd y;
  truth.Sample(1000, rng, &q, &y);
  ChainPosteriors post;
  ASSERT_TRUE(learned->Posteriors(y, &post));
  EXPECT_GT(testing::AccuracyBestPermutation(post.gamma, q, s), 0.95);
  const double ll_true = truth.LogLikelihood(y) / 1000.0;
  const double ll_learned = learned->LogLikelihood(y) / 1000.0;
  EXPECT_NEAR(ll_learned, ll_true, 0.05) << "held-out log-likelihood per step";
  // Transition matrix rows are distributions and sticky like the truth.
  for (int i = 0; i < s; ++i) {
    EXPECT_NEAR(learned->transition().row(i).sum(), 1.0, 1e-9);
    EXPECT_GT(learned->transition().row(i).maxCoeff(), 0.7);
  }
}

TEST(GaussianHmmTest, RecoversPlantedDiagonalHmm) { CheckRecovery(false); }
TEST(GaussianHmmTest, RecoversPlantedFullCovarianceHmm) { CheckRecovery(true); }

TEST(GaussianHmmTest, RejectsBadInput) {
  HmmTrainParams p;
  p.num_states = 2;
  EXPECT_EQ(GaussianHmm::Train({}, p).status().code(), absl::StatusCode::kInvalidArgument);
  Eigen::MatrixXd a = Eigen::MatrixXd::Random(20, 6);
  Eigen::MatrixXd b = Eigen::MatrixXd::Random(20, 5);
  auto st = GaussianHmm::Train({a, b}, p).status();
  EXPECT_EQ(st.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(st.message().find("sequences[1]"), std::string::npos) << st;
  a(3, 2) = std::numeric_limits<double>::quiet_NaN();
  st = GaussianHmm::Train({a}, p).status();
  EXPECT_EQ(st.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(st.message().find("NaN"), std::string::npos) << st;
  EXPECT_EQ(GaussianHmm::Train({Eigen::MatrixXd(0, 6)}, p).status().code(),
            absl::StatusCode::kInvalidArgument);
}

TEST(KMeansTest, SeparatesClusters) {
  Eigen::MatrixXd x(200, 2);
  std::mt19937_64 rng(1);
  std::normal_distribution<double> nd;
  for (int i = 0; i < 200; ++i) x.row(i) << (i < 100 ? -10 : 10) + nd(rng), nd(rng);
  std::vector<int> a;
  KMeansPlusPlus(x, 2, 5, rng, &a);
  for (int i = 1; i < 100; ++i) EXPECT_EQ(a[i], a[0]);
  for (int i = 101; i < 200; ++i) EXPECT_EQ(a[i], a[100]);
  EXPECT_NE(a[0], a[100]);
}

}  // namespace
}  // namespace kinemo::inference
