#include "services/inference/core/model_store.h"

#include <filesystem>
#include <fstream>
#include <random>

#include <gtest/gtest.h>

#include "tests/unit/inference/planted.h"

namespace kinemo::inference {
namespace {

namespace fs = std::filesystem;

class ModelStoreTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::path(::testing::TempDir()) /
           ("kinemo_store_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    testing::PlantedPipeline planted(3, 0, 5);
    std::mt19937_64 rng(2);
    data_ = {planted.Sample(200, rng, nullptr), planted.Sample(200, rng, nullptr)};
    params_.num_states = 3;
    params_.window = 2;
    params_.num_clusters = 4;
    params_.hmm_restarts = 1;
    auto m = RemappedModel::Train(data_, params_, nullptr, &report_);
    ASSERT_TRUE(m.ok()) << m.status();
    model_ = std::make_unique<RemappedModel>(*std::move(m));
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
  std::vector<PairedSequence> data_;
  ModelTrainParams params_;
  TrainReport report_;
  std::unique_ptr<RemappedModel> model_;
};

TEST_F(ModelStoreTest, SaveLoadListRoundTrip) {
  auto store = ModelStore::Open(dir_.string());
  ASSERT_TRUE(store.ok()) << store.status();
  v1::ModelInfo info = MakeModelInfo(*model_, params_, report_, 2, "planted test data");
  info.set_model_id("planted");
  auto saved = (*store)->Save(*model_, info, false);
  ASSERT_TRUE(saved.ok()) << saved.status();
  EXPECT_EQ(saved->version(), 1u);
  EXPECT_EQ((*store)->Save(*model_, info, false).status().code(), absl::StatusCode::kAlreadyExists);
  auto v2 = (*store)->Save(*model_, info, true);
  ASSERT_TRUE(v2.ok());
  EXPECT_EQ(v2->version(), 2u);

  // A fresh store reads the files back.
  auto store2 = ModelStore::Open(dir_.string());
  auto loaded = (*store2)->Load("planted", 0);
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  EXPECT_EQ(loaded->info.version(), 2u);
  EXPECT_EQ(loaded->info.description(), "planted test data");
  EXPECT_EQ(loaded->info.training_steps(), 400u);
  EXPECT_EQ(loaded->info.params().num_states(), 3u);
  auto a = model_->Evaluate(data_[0]);
  auto b = loaded->model->Evaluate(data_[0]);
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_DOUBLE_EQ(a->crf_ll_per_step, b->crf_ll_per_step);
  EXPECT_DOUBLE_EQ(a->hmm_ll_per_step, b->hmm_ll_per_step);

  auto latest = (*store2)->List(false);
  ASSERT_TRUE(latest.ok());
  ASSERT_EQ(latest->size(), 1u);
  auto all = (*store2)->List(true);
  ASSERT_EQ(all->size(), 2u);
  EXPECT_EQ((*all)[0].version(), 1u);

  const auto params = MakeModelParameters(*loaded->model);
  ASSERT_EQ(params.transition_probabilities_size(), 9);
  double row = 0;
  for (int j = 0; j < 3; ++j) row += params.transition_probabilities(j);
  EXPECT_NEAR(row, 1.0, 1e-12);
  EXPECT_EQ(params.states_size(), 3);
  EXPECT_EQ(params.states(0).covariance_size(), 6);
}

TEST_F(ModelStoreTest, Errors) {
  auto store = ModelStore::Open(dir_.string());
  ASSERT_TRUE(store.ok());
  auto st = (*store)->Load("nope", 0).status();
  EXPECT_EQ(st.code(), absl::StatusCode::kNotFound);
  EXPECT_NE(st.message().find("nope"), std::string::npos);
  EXPECT_EQ((*store)->Load("Bad Id!", 0).status().code(), absl::StatusCode::kInvalidArgument);
  v1::ModelInfo info;
  info.set_model_id("m");
  ASSERT_TRUE((*store)->Save(*model_, info, false).ok());
  EXPECT_EQ((*store)->Load("m", 7).status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ((*store)->Delete("m", 3).status().code(), absl::StatusCode::kNotFound);
  // A corrupt file is refused with its path.
  const std::string bad = (dir_ / "bad.kmodel").string();
  std::ofstream(bad) << "not a model";
  EXPECT_EQ(ReadModelFile(bad).status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(ReadModelFile((dir_ / "missing.kmodel").string()).status().code(),
            absl::StatusCode::kNotFound);
}

TEST_F(ModelStoreTest, LayoutIsTheArtifactStoreAndTheFolderIdWins) {
  auto store = ModelStore::Open(dir_.string());
  ASSERT_TRUE(store.ok()) << store.status();
  v1::ModelInfo info = MakeModelInfo(*model_, params_, report_, 2, "planted");
  info.set_model_id("alpha");
  ASSERT_TRUE((*store)->Save(*model_, info, false).ok());
  const fs::path file = dir_ / "models" / "alpha" / "1" / "model.kmodel";
  ASSERT_TRUE(fs::exists(file));
  ASSERT_TRUE(fs::exists(dir_ / "models" / "alpha" / "1" / "artifact.json"));
  auto meta = (*store)->ListArtifacts("alpha", false);
  ASSERT_TRUE(meta.ok() && meta->size() == 1u);
  EXPECT_NE((*meta)[0].summary_json.find("\"num_states\":3"), std::string::npos) << (*meta)[0].summary_json;

  // A copy of the folder under another id (as a user would do by hand): the
  // copy is listed and loaded by its folder's id, not the id inside the file.
  fs::create_directories(dir_ / "models" / "beta");
  fs::copy(dir_ / "models" / "alpha" / "1", dir_ / "models" / "beta" / "1", fs::copy_options::recursive);
  auto reopened = ModelStore::Open(dir_.string());
  ASSERT_TRUE(reopened.ok());
  auto list = (*reopened)->List(false);
  ASSERT_TRUE(list.ok()) << list.status();
  ASSERT_EQ(list->size(), 2u);
  EXPECT_EQ((*list)[0].model_id(), "alpha");
  EXPECT_EQ((*list)[1].model_id(), "beta");
  auto beta = (*reopened)->Load("beta", 0);
  ASSERT_TRUE(beta.ok()) << beta.status();
  EXPECT_EQ(beta->info.model_id(), "beta");
  EXPECT_EQ(beta->info.version(), 1u);
}

TEST_F(ModelStoreTest, ImportsTheOldLayoutOnce) {
  v1::ModelInfo info = MakeModelInfo(*model_, params_, report_, 2, "old layout");
  info.set_model_id("inside-the-file");
  for (int v : {1, 2}) {
    info.set_version(static_cast<std::uint32_t>(v));
    ASSERT_TRUE(WriteModelFile((dir_ / "legacy" / ("v" + std::to_string(v) + ".kmodel")).string(),
                               EncodeModel(*model_, info)).ok());
  }
  auto store = ModelStore::Open(dir_.string());
  ASSERT_TRUE(store.ok()) << store.status();
  auto all = (*store)->List(true);
  ASSERT_TRUE(all.ok()) << all.status();
  ASSERT_EQ(all->size(), 2u);
  EXPECT_EQ((*all)[0].model_id(), "legacy");
  EXPECT_EQ((*all)[1].version(), 2u);
  // Opening again imports nothing more.
  auto again = ModelStore::Open(dir_.string());
  ASSERT_TRUE(again.ok());
  EXPECT_EQ((*again)->List(true)->size(), 2u);
}

TEST_F(ModelStoreTest, CommitPushedValidatesAndRenames) {
  auto store = ModelStore::Open(dir_.string());
  ASSERT_TRUE(store.ok());
  auto artifacts = store::ArtifactStore::Open(dir_.string());
  ASSERT_TRUE(artifacts.ok());
  v1::ModelInfo info = MakeModelInfo(*model_, params_, report_, 2, "trained elsewhere");
  info.set_model_id("file-id");
  std::string bytes;
  ASSERT_TRUE(EncodeModel(*model_, info).SerializeToString(&bytes));

  auto draft = (*artifacts)->Begin("models", "pushed");
  ASSERT_TRUE(draft.ok());
  ASSERT_TRUE(draft->WriteFile("model.kmodel", bytes).ok());
  auto loaded = (*store)->CommitPushed(*std::move(draft), "header.files[0]", false, "", {});
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  EXPECT_EQ(loaded->info.model_id(), "pushed");
  EXPECT_EQ(loaded->info.description(), "trained elsewhere");
  // The stored file carries the pushed id.
  auto file = ReadModelFile((dir_ / "models" / "pushed" / "1" / "model.kmodel").string());
  ASSERT_TRUE(file.ok());
  EXPECT_EQ(file->info().model_id(), "pushed");

  // Garbage, and a well-formed file whose matrices do not fit: refused naming the field.
  for (const std::string& bad : {std::string("\xff\xfe not a model"), std::string()}) {
    auto d = (*artifacts)->Begin("models", "broken");
    ASSERT_TRUE(d.ok());
    ASSERT_TRUE(d->WriteFile("model.kmodel", bad).ok());
    auto r = (*store)->CommitPushed(*std::move(d), "header.files[0]", false, "", {});
    EXPECT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_EQ(r.status().message().rfind("header.files[0]: ", 0), 0u) << r.status();
  }
  v1::ModelFile wrong = EncodeModel(*model_, info);
  wrong.mutable_hmm()->mutable_transition()->set_rows(7);
  ASSERT_TRUE(wrong.SerializeToString(&bytes));
  auto d = (*artifacts)->Begin("models", "broken");
  ASSERT_TRUE(d->WriteFile("model.kmodel", bytes).ok());
  auto r = (*store)->CommitPushed(*std::move(d), "header.files[0]", false, "", {});
  EXPECT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(r.status().message().find("hmm.transition"), std::string::npos) << r.status();
  EXPECT_EQ((*store)->Load("broken", 0).status().code(), absl::StatusCode::kNotFound);

  // Deleting drops the cached model.
  ASSERT_TRUE((*store)->Delete("pushed", 0).ok());
  EXPECT_EQ((*store)->Load("pushed", 1).status().code(), absl::StatusCode::kNotFound);
}

}  // namespace
}  // namespace kinemo::inference
