#include "services/inference/core/remapped_model.h"

#include <limits>
#include <random>

#include <gtest/gtest.h>

#include "tests/unit/inference/planted.h"
#include "tests/unit/inference/test_util.h"

namespace kinemo::inference {
namespace {

class RemappedModelTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    planted_ = new testing::PlantedPipeline(4, 0, 21);
    std::mt19937_64 rng(77);
    train_ = new std::vector<PairedSequence>;
    for (int k = 0; k < 6; ++k) train_->push_back(planted_->Sample(400, rng, nullptr));
    test_ = new PairedSequence(planted_->Sample(1500, rng, &test_states_));
    ModelTrainParams p;
    p.num_states = 4;
    p.window = 3;
    p.num_clusters = 6;
    p.hmm_restarts = 3;
    p.crf_l2 = 0.1;
    report_ = new TrainReport;
    auto m = RemappedModel::Train(*train_, p, nullptr, report_);
    ASSERT_TRUE(m.ok()) << m.status();
    model_ = new RemappedModel(*std::move(m));
  }
  static void TearDownTestSuite() {
    delete planted_;
    delete train_;
    delete test_;
    delete model_;
    delete report_;
  }
  static testing::PlantedPipeline* planted_;
  static std::vector<PairedSequence>* train_;
  static PairedSequence* test_;
  static std::vector<int> test_states_;
  static RemappedModel* model_;
  static TrainReport* report_;
};
testing::PlantedPipeline* RemappedModelTest::planted_ = nullptr;
std::vector<PairedSequence>* RemappedModelTest::train_ = nullptr;
PairedSequence* RemappedModelTest::test_ = nullptr;
std::vector<int> RemappedModelTest::test_states_;
RemappedModel* RemappedModelTest::model_ = nullptr;
TrainReport* RemappedModelTest::report_ = nullptr;

TEST_F(RemappedModelTest, HmmStatesMatchPlantedStates) {
  ChainPosteriors post;
  ASSERT_TRUE(model_->hmm().Posteriors(test_->outputs, &post));
  EXPECT_GT(testing::AccuracyBestPermutation(post.gamma, test_states_, 4), 0.97);
}

TEST_F(RemappedModelTest, CrfInfersPlantedStatesFromProsodyAlone) {
  auto r = model_->Infer(test_->inputs, true, true);
  ASSERT_TRUE(r.ok()) << r.status();
  const double acc = testing::AccuracyBestPermutation(r->smoothed, test_states_, 4);
  RecordProperty("crf_gamma_accuracy", std::to_string(acc));
  EXPECT_GT(acc, 0.75);
  for (Eigen::Index t = 0; t < r->smoothed.rows(); ++t) {
    EXPECT_NEAR(r->smoothed.row(t).sum(), 1.0, 1e-9);
    EXPECT_NEAR(r->filtered.row(t).sum(), 1.0, 1e-9);
  }
  EXPECT_EQ(r->viterbi.size(), test_->inputs.size());
}

TEST_F(RemappedModelTest, HeldOutLikelihoodCloseToGeneratingModel) {
  auto sc = model_->Evaluate(*test_);
  ASSERT_TRUE(sc.ok()) << sc.status();
  const double truth = planted_->TrueLogLikelihoodPerStep(*test_);
  std::cout << "held-out ll/step: crf " << sc->crf_ll_per_step << " remapped-hmm "
            << sc->hmm_ll_per_step << " generating model " << truth << "\n";
  EXPECT_NEAR(sc->crf_ll_per_step, truth, 0.15);
  EXPECT_LE(sc->crf_ll_per_step, truth + 0.1);
  EXPECT_TRUE(std::isfinite(sc->hmm_ll_per_step));
  EXPECT_GT(report_->crf_ll_per_step, -1e9);
}

TEST_F(RemappedModelTest, OnlineFilterMatchesOfflineForward) {
  const std::span<const ProsodyStep> xs(test_->inputs.data(), 200);
  auto offline = model_->Infer(xs, true, false);
  ASSERT_TRUE(offline.ok());
  OnlineFilter filter(*model_);
  std::vector<double> alpha(4);
  Eigen::Index step = 0;
  auto check = [&] {
    for (int i = 0; i < 4; ++i) EXPECT_NEAR(alpha[i], offline->filtered(step, i), 1e-10);
    ++step;
  };
  for (const auto& x : xs) {
    if (filter.Push(x, alpha)) check();
  }
  EXPECT_EQ(step, 200 - model_->lookahead());
  while (filter.Finish(alpha)) check();
  EXPECT_EQ(step, 200);
}

TEST_F(RemappedModelTest, RejectsBadInput) {
  PairedSequence bad = *test_;
  bad.inputs[5].intensity_mean_db = std::numeric_limits<double>::quiet_NaN();
  auto st = model_->Evaluate(bad).status();
  EXPECT_EQ(st.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(st.message().find("inputs[5].intensity_mean_db"), std::string::npos) << st;

  EXPECT_EQ(model_->Infer({}, false, false).status().code(), absl::StatusCode::kInvalidArgument);

  bad = *test_;
  bad.outputs.conservativeResize(bad.outputs.rows() - 1, 6);
  st = model_->Evaluate(bad).status();
  EXPECT_EQ(st.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(st.message().find("steps but inputs have"), std::string::npos) << st;

  bad = *test_;
  bad.outputs = Eigen::MatrixXd::Zero(bad.outputs.rows(), 5);
  EXPECT_EQ(model_->Evaluate(bad).status().code(), absl::StatusCode::kInvalidArgument);

  bad = *test_;
  bad.inputs[0].voiced = true;
  bad.inputs[0].f0_mean_hz = -3;
  EXPECT_EQ(model_->Infer(bad.inputs, false, false).status().code(),
            absl::StatusCode::kInvalidArgument);

  ModelTrainParams p;
  p.window = 0;
  EXPECT_EQ(RemappedModel::Train(*train_, p, nullptr, nullptr).status().code(),
            absl::StatusCode::kInvalidArgument);
  p = {};
  EXPECT_EQ(RemappedModel::Train({}, p, nullptr, nullptr).status().code(),
            absl::StatusCode::kInvalidArgument);
}

TEST_F(RemappedModelTest, CancelStopsTraining) {
  ModelTrainParams p;
  p.num_states = 4;
  p.hmm_restarts = 1;
  auto st = RemappedModel::Train(
      *train_, p, [](std::string_view stage, double, std::string_view) { return stage != "crf_optimize"; },
      nullptr);
  EXPECT_EQ(st.status().code(), absl::StatusCode::kCancelled);
}

}  // namespace
}  // namespace kinemo::inference
