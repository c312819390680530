// The cube catalog over the artifact store: stored cubes override the
// options' ones and come back when the catalog is opened again, the default
// cube persists, deletion falls back, pushed files are validated and renamed,
// and without a store_dir the versions live in a temp folder removed at the end.
#include "services/cube_tracker/core/cube_catalog.h"

#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>

namespace kinemo::cube {
namespace {

namespace fs = std::filesystem;

const std::string kData = KINEMO_TEST_DATA_DIR;

class CubeCatalogTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::path(::testing::TempDir()) /
           ("kinemo_cubes_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    auto vleo = LoadCubeModel(kData + "/cube/vleo.cube");
    ASSERT_TRUE(vleo.ok()) << vleo.status();
    vleo_ = *vleo;
  }
  void TearDown() override { fs::remove_all(dir_); }

  CubeCatalog::Options WithStore() {
    CubeCatalog::Options o;
    o.cubes = {vleo_};
    o.store_dir = (dir_ / "store").string();
    return o;
  }

  fs::path dir_;
  CubeModel vleo_;
};

TEST_F(CubeCatalogTest, ConfiguredCubesPersistAndOverrideTheOptions) {
  {
    auto c = CubeCatalog::Open(WithStore());
    ASSERT_TRUE(c.ok()) << c.status();
    EXPECT_FALSE((*c)->in_memory());
    EXPECT_EQ((*c)->default_id(), "vleo");
    CubeModel big = vleo_;
    big.cube_size_m = 0.08;
    big.marker_size_m = 0.06;
    EXPECT_EQ((*c)->Configure(big, false, false).status().code(), absl::StatusCode::kAlreadyExists);
    ASSERT_TRUE((*c)->Configure(big, false, true).ok());
    CubeModel other = vleo_;
    other.name = "table";
    auto stored = (*c)->Configure(other, true, false);
    ASSERT_TRUE(stored.ok()) << stored.status();
    EXPECT_TRUE(stored->is_default);
    EXPECT_EQ(stored->meta.version, 1u);
    EXPECT_TRUE(fs::exists(dir_ / "store" / "cubes" / "table" / "1" / "cube.textproto"));
  }
  // Opened again (a restart): the stored versions win, the default persists.
  auto c = CubeCatalog::Open(WithStore());
  ASSERT_TRUE(c.ok()) << c.status();
  ASSERT_NE((*c)->Find("vleo"), nullptr);
  EXPECT_DOUBLE_EQ((*c)->Find("vleo")->cube_size_m, 0.08);
  ASSERT_NE((*c)->Find("table"), nullptr);
  EXPECT_EQ((*c)->default_id(), "table");
  EXPECT_EQ((*c)->Default()->name, "table");

  // Deleting every stored version of vleo serves the options' vleo again;
  // deleting the default falls back to the options' default.
  ASSERT_TRUE((*c)->Delete("vleo", 0).ok());
  EXPECT_DOUBLE_EQ((*c)->Find("vleo")->cube_size_m, 0.06);
  ASSERT_TRUE((*c)->Delete("table", 0).ok());
  EXPECT_EQ((*c)->Find("table"), nullptr);
  EXPECT_EQ((*c)->default_id(), "vleo");
  EXPECT_EQ((*c)->Delete("table", 0).status().code(), absl::StatusCode::kNotFound);
}

TEST_F(CubeCatalogTest, PushedFilesAreValidatedAndTakeThePushedId) {
  auto c = CubeCatalog::Open(WithStore());
  ASSERT_TRUE(c.ok());
  std::ifstream in(kData + "/cube/vleo.cube");
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  auto draft = (*c)->artifacts().Begin("cubes", "desk");
  ASSERT_TRUE(draft.ok());
  ASSERT_TRUE(draft->WriteFile("cube.textproto", text).ok());
  auto stored = (*c)->CommitPushed(*std::move(draft), "header.files[0]", false, "pushed");
  ASSERT_TRUE(stored.ok()) << stored.status();
  EXPECT_EQ(stored->model->name, "desk");
  EXPECT_EQ(stored->meta.description, "pushed");
  // The stored text names the pushed id.
  auto reread = LoadCubeModel((dir_ / "store" / "cubes" / "desk" / "1" / "cube.textproto").string());
  ASSERT_TRUE(reread.ok()) << reread.status();
  EXPECT_EQ(reread->name, "desk");

  const std::string no_faces = "dictionary: \"DICT_4X4_50\"\ncube_size_m: 0.06\nmarker_size_m: 0.045\n";
  for (const std::string& bad : {std::string("cube_size_m: oops"), no_faces}) {
    auto d = (*c)->artifacts().Begin("cubes", "broken");
    ASSERT_TRUE(d->WriteFile("cube.textproto", bad).ok());
    auto r = (*c)->CommitPushed(*std::move(d), "header.files[0]", false, "");
    EXPECT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_EQ(r.status().message().rfind("header.files[0]: ", 0), 0u) << r.status();
  }
  EXPECT_EQ((*c)->Find("broken"), nullptr);
  EXPECT_EQ((*c)->List("broken", true)->size(), 0u);
}

TEST_F(CubeCatalogTest, WithoutAStoreDirVersionsLiveInATempFolderRemovedAtTheEnd) {
  CubeCatalog::Options o;
  o.cubes = {vleo_};
  std::string root;
  {
    auto c = CubeCatalog::Open(o);
    ASSERT_TRUE(c.ok()) << c.status();
    EXPECT_TRUE((*c)->in_memory());
    root = (*c)->artifacts().root();
    CubeModel other = vleo_;
    other.name = "desk";
    ASSERT_TRUE((*c)->Configure(other, false, false).ok());
    EXPECT_NE((*c)->Find("desk"), nullptr);
    EXPECT_EQ((*c)->List("", false)->size(), 1u);
    EXPECT_TRUE(fs::exists(root));
  }
  EXPECT_FALSE(fs::exists(root));
}

}  // namespace
}  // namespace kinemo::cube
