#include "services/inference/core/remapped_crf.h"

#include <random>

#include <gtest/gtest.h>

#include "tests/unit/inference/test_util.h"

namespace kinemo::inference {
namespace {

RowMatrix RandomPosteriors(int n, int k, std::mt19937_64& rng) {
  std::uniform_int_distribution<int> pick(0, k - 1);
  RowMatrix p = RowMatrix::Constant(n, k, 0.15 / (k - 1));
  for (int t = 0; t < n; ++t) p(t, pick(rng)) = 0.85;
  return p;
}

CrfTarget HardTarget(const RowMatrix& features, const std::vector<int>& q, int s) {
  CrfTarget t;
  t.features = features;
  t.gamma = RowMatrix::Zero(features.rows(), s);
  t.xi_sum = Eigen::MatrixXd::Zero(s, s);
  for (size_t i = 0; i < q.size(); ++i) {
    t.gamma(static_cast<Eigen::Index>(i), q[i]) = 1.0;
    if (i > 0) t.xi_sum(q[i - 1], q[i]) += 1.0;
  }
  return t;
}

// log P(Q | X) of a path under a CRF.
double PathLogProb(const RemappedCrf& crf, const RowMatrix& f, const std::vector<int>& q) {
  const RowMatrix phi = crf.LogNode(f);
  double s = crf.initial_weights()(q[0]) + phi(0, q[0]);
  for (size_t t = 1; t < q.size(); ++t)
    s += crf.transition_weights()(q[t - 1], q[t]) + phi(static_cast<Eigen::Index>(t), q[t]);
  return s - crf.LogPartition(f);
}

TEST(RemappedCrfTest, WindowFeaturesAreCentredAndZeroPadded) {
  RowMatrix post(3, 2);
  post << 1, 0, 0, 1, 0.5, 0.5;
  const RowMatrix f = RemappedCrf::WindowFeatures(post, 4);  // offsets -2..1
  ASSERT_EQ(f.cols(), 9);
  // t = 1: offsets -2 (out), -1 (t0), 0 (t1), +1 (t2), bias.
  Eigen::RowVectorXd expect(9);
  expect << 0, 0, 1, 0, 0, 1, 0.5, 0.5, 1;
  EXPECT_EQ(f.row(1), expect);
  EXPECT_EQ(RemappedCrf::Lookahead(4), 1);
  EXPECT_EQ(RemappedCrf::Lookahead(1), 0);
  EXPECT_EQ(RemappedCrf::Lookahead(5), 2);
}

TEST(RemappedCrfTest, GradientMatchesFiniteDifferences) {
  std::mt19937_64 rng(5);
  const int s = 3, k = 4, w = 3;
  const int f = RemappedCrf::FeatureCount(w, k);
  std::vector<CrfTarget> targets;
  for (int q = 0; q < 2; ++q) {
    CrfTarget t;
    t.features = RemappedCrf::WindowFeatures(RandomPosteriors(30, k, rng), w);
    // Soft targets: a random chain posterior.
    RowMatrix ln = RowMatrix::Random(30, s);
    ChainPosteriors post;
    ChainForwardBackward(ln, Eigen::MatrixXd::Random(s, s).array().abs() + 0.2,
                         Eigen::VectorXd::Ones(s), true, &post);
    t.gamma = post.gamma;
    t.xi_sum = post.xi_sum;
    targets.push_back(t);
  }
  Eigen::VectorXd theta = 0.5 * Eigen::VectorXd::Random(s * s + s + s * f);
  Eigen::VectorXd g;
  RemappedCrf::Objective(targets, s, f, 0.3, theta, &g);
  Eigen::VectorXd tmp;
  double max_err = 0;
  for (Eigen::Index i = 0; i < theta.size(); ++i) {
    const double h = 1e-5;
    Eigen::VectorXd tp = theta, tm = theta;
    tp(i) += h;
    tm(i) -= h;
    const double num = (RemappedCrf::Objective(targets, s, f, 0.3, tp, &tmp) -
                        RemappedCrf::Objective(targets, s, f, 0.3, tm, &tmp)) /
                       (2 * h);
    max_err = std::max(max_err, std::abs(num - g(i)));
  }
  EXPECT_LT(max_err, 1e-7);
}

TEST(RemappedCrfTest, RecoversPlantedCrf) {
  std::mt19937_64 rng(9);
  std::normal_distribution<double> nd;
  const int s = 3, k = 4, w = 3;
  const int f = RemappedCrf::FeatureCount(w, k);
  Eigen::MatrixXd wt(s, s);
  for (int i = 0; i < s; ++i)
    for (int j = 0; j < s; ++j) wt(i, j) = (i == j ? 1.5 : 0.0) + 0.5 * nd(rng);
  RowMatrix u(s, f);
  for (int i = 0; i < s; ++i)
    for (int c = 0; c < f; ++c) u(i, c) = 1.5 * nd(rng);
  const RemappedCrf truth =
      *RemappedCrf::FromParameters(w, k, wt, Eigen::VectorXd::Zero(s), u);
  std::vector<CrfTarget> targets;
  for (int q = 0; q < 30; ++q) {
    const RowMatrix feat = RemappedCrf::WindowFeatures(RandomPosteriors(200, k, rng), w);
    targets.push_back(HardTarget(feat, testing::SampleCrf(truth, feat, rng), s));
  }
  CrfTrainParams p;
  p.l2 = 0.1;
  auto learned = RemappedCrf::Train(targets, s, w, k, p);
  ASSERT_TRUE(learned.ok()) << learned.status();
  double ll_true = 0, ll_learned = 0, acc_true = 0, acc_learned = 0;
  int n = 0;
  for (int q = 0; q < 10; ++q) {
    const RowMatrix feat = RemappedCrf::WindowFeatures(RandomPosteriors(300, k, rng), w);
    const auto path = testing::SampleCrf(truth, feat, rng);
    ll_true += PathLogProb(truth, feat, path);
    ll_learned += PathLogProb(*learned, feat, path);
    ChainPosteriors a, b;
    truth.Posteriors(feat, &a);
    learned->Posteriors(feat, &b);
    for (int t = 0; t < 300; ++t) {
      Eigen::Index ia, ib;
      a.gamma.row(t).maxCoeff(&ia);
      b.gamma.row(t).maxCoeff(&ib);
      acc_true += ia == path[t];
      acc_learned += ib == path[t];
    }
    n += 300;
  }
  EXPECT_NEAR(ll_learned / n, ll_true / n, 0.03);
  EXPECT_GT(acc_learned / n, acc_true / n - 0.02);
  EXPECT_GT(acc_true / n, 0.6);  // the planted problem is informative
}

TEST(RemappedCrfTest, TransitionPowers) {
  Eigen::MatrixXd wt = Eigen::MatrixXd::Random(4, 4);
  const RemappedCrf crf = *RemappedCrf::FromParameters(1, 2, wt, Eigen::VectorXd::Zero(4),
                                                       RowMatrix::Zero(4, 3));
  const Eigen::MatrixXd t = crf.NormalizedTransition();
  for (int i = 0; i < 4; ++i) EXPECT_NEAR(t.row(i).sum(), 1.0, 1e-12);
  EXPECT_NEAR(t(1, 2), std::exp(wt(1, 2)) / wt.row(1).array().exp().sum(), 1e-12);
  EXPECT_LT((crf.TransitionPower(5) - t * t * t * t * t).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_LT((crf.TransitionPower(0) - Eigen::MatrixXd::Identity(4, 4)).cwiseAbs().maxCoeff(),
            1e-15);
}

TEST(RemappedCrfTest, RejectsMismatchedTargets) {
  CrfTarget t;
  t.features = RowMatrix::Ones(5, 7);  // wrong F for w=1, K=2 (3)
  t.gamma = RowMatrix::Ones(5, 2) / 2;
  t.xi_sum = Eigen::MatrixXd::Ones(2, 2);
  auto st = RemappedCrf::Train({t}, 2, 1, 2, {}).status();
  EXPECT_EQ(st.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(RemappedCrf::Train({}, 2, 1, 2, {}).status().code(),
            absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace kinemo::inference
