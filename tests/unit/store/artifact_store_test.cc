// The artifact store on a real folder: versions, atomic commits, drafts left
// by a crash, listing by the folder's id, deletion, seeding.
#include "common/store/artifact_store.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>

#include "absl/strings/match.h"
#include "common/testing/process.h"

namespace kinemo::store {
namespace {

namespace fs = std::filesystem;

std::string Slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

StatusOr<ArtifactMeta> PutText(ArtifactStore& s, std::string_view kind, std::string_view id, std::string_view text,
                               bool overwrite = false) {
  KINEMO_ASSIGN_OR_RETURN(Draft d, s.Begin(kind, id));
  KINEMO_RETURN_IF_ERROR(d.WriteFile("data.txt", text));
  ArtifactMeta meta;
  meta.description = kinemo::StrCat("text ", text);
  meta.summary_json = R"({"chars": 3})";
  return s.Commit(std::move(d), meta, overwrite);
}

TEST(ArtifactStore, VersionsAreNumberedFoldersAndTheNewestIsServed) {
  testing::TempDir dir;
  auto store = ArtifactStore::Open(dir.File("store"));
  ASSERT_TRUE(store.ok()) << store.status();
  auto v1 = PutText(**store, kModels, "m", "one");
  ASSERT_TRUE(v1.ok()) << v1.status();
  EXPECT_EQ(v1->version, 1u);
  EXPECT_EQ(Slurp(dir.File("store/models/m/1/data.txt")), "one");
  EXPECT_TRUE(fs::exists(dir.File("store/models/m/1/artifact.json")));

  // Without overwrite a second push of the same id is refused and changes nothing.
  auto again = PutText(**store, kModels, "m", "two");
  EXPECT_EQ(again.status().code(), absl::StatusCode::kAlreadyExists);
  EXPECT_FALSE(fs::exists(dir.File("store/models/m/2")));

  auto v2 = PutText(**store, kModels, "m", "two", /*overwrite=*/true);
  ASSERT_TRUE(v2.ok()) << v2.status();
  EXPECT_EQ(v2->version, 2u);
  auto newest = (*store)->Get(kModels, "m");
  ASSERT_TRUE(newest.ok());
  EXPECT_EQ(newest->version, 2u);
  EXPECT_EQ(newest->description, "text two");
  EXPECT_EQ(newest->summary_json, R"({"chars":3})");
  ASSERT_EQ(newest->files.size(), 1u);
  EXPECT_EQ(newest->files[0].name, "data.txt");
  EXPECT_EQ(newest->files[0].size_bytes, 3u);
  EXPECT_EQ(Slurp((*store)->FilePath(newest->ref(), "data.txt")), "two");
  auto old = (*store)->Get(kModels, "m", 1);
  ASSERT_TRUE(old.ok());
  EXPECT_EQ(Slurp((*store)->FilePath(old->ref(), "data.txt")), "one");
  EXPECT_EQ((*store)->Get(kModels, "m", 3).status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ((*store)->Get(kModels, "nope").status().code(), absl::StatusCode::kNotFound);
}

TEST(ArtifactStore, ReopenedStoreListsWhatWasCommittedAndDropsDrafts) {
  testing::TempDir dir;
  {
    auto store = ArtifactStore::Open(dir.File("s"));
    ASSERT_TRUE(store.ok());
    ASSERT_TRUE(PutText(**store, kControllers, "b", "x").ok());
    ASSERT_TRUE(PutText(**store, kControllers, "a", "y").ok());
    ASSERT_TRUE(PutText(**store, kControllers, "a", "z", true).ok());
    ASSERT_TRUE(PutText(**store, kLibraries, "lib", "w").ok());
    // A draft that never commits (as if the process died mid-upload).
    auto d = (*store)->Begin(kControllers, "c");
    ASSERT_TRUE(d.ok());
    ASSERT_TRUE(d->Append("part.bin", "half").ok());
    const std::string staged = d->dir();
    // Simulate a crash: the draft's folder stays on disk.
    fs::copy(staged, dir.File("s/.staging/crashed"), fs::copy_options::recursive);
  }
  // A version folder without artifact.json (not committed) is not a version.
  fs::create_directories(dir.File("s/controllers/a/7"));
  auto store = ArtifactStore::Open(dir.File("s"));
  ASSERT_TRUE(store.ok());
  EXPECT_FALSE(fs::exists(dir.File("s/.staging/crashed")));
  auto list = (*store)->List(kControllers);
  ASSERT_TRUE(list.ok());
  ASSERT_EQ(list->size(), 2u);
  EXPECT_EQ((*list)[0].id, "a");
  EXPECT_EQ((*list)[0].version, 2u);
  EXPECT_EQ((*list)[1].id, "b");
  auto all = (*store)->List("", "", /*all_versions=*/true);
  ASSERT_TRUE(all.ok());
  EXPECT_EQ(all->size(), 4u);
  auto c = (*store)->Get(kControllers, "c");
  EXPECT_EQ(c.status().code(), absl::StatusCode::kNotFound);
}

TEST(ArtifactStore, ListReportsTheFolderIdNotTheOneInsideTheFile) {
  testing::TempDir dir;
  auto store = ArtifactStore::Open(dir.File("s"));
  ASSERT_TRUE(store.ok());
  ASSERT_TRUE(PutText(**store, kModels, "original", "x").ok());
  // A user copies the folder under another name.
  fs::copy(dir.File("s/models/original"), dir.File("s/models/renamed"), fs::copy_options::recursive);
  auto m = (*store)->Get(kModels, "renamed");
  ASSERT_TRUE(m.ok()) << m.status();
  EXPECT_EQ(m->id, "renamed");
}

TEST(ArtifactStore, DeleteRemovesOneOrAllVersions) {
  testing::TempDir dir;
  auto store = ArtifactStore::Open(dir.File("s"));
  ASSERT_TRUE(store.ok());
  ASSERT_TRUE(PutText(**store, kCubes, "c", "1").ok());
  ASSERT_TRUE(PutText(**store, kCubes, "c", "2", true).ok());
  auto removed = (*store)->Delete(kCubes, "c", 2);
  ASSERT_TRUE(removed.ok()) << removed.status();
  ASSERT_EQ(removed->size(), 1u);
  EXPECT_EQ((*store)->Get(kCubes, "c")->version, 1u);  // back to the previous version
  EXPECT_EQ((*store)->Delete(kCubes, "c", 5).status().code(), absl::StatusCode::kNotFound);
  ASSERT_TRUE((*store)->Delete(kCubes, "c", 0).ok());
  EXPECT_EQ((*store)->Get(kCubes, "c").status().code(), absl::StatusCode::kNotFound);
  EXPECT_FALSE(fs::exists(dir.File("s/cubes/c")));
}

TEST(ArtifactStore, ImportSeedKeepsVersionsAndNeverReplacesWhatWasPushed) {
  testing::TempDir dir;
  auto seed = ArtifactStore::Open(dir.File("seed"));
  ASSERT_TRUE(seed.ok());
  ASSERT_TRUE(PutText(**seed, kLibraries, "bundled", "a").ok());
  ASSERT_TRUE(PutText(**seed, kLibraries, "bundled", "b", true).ok());
  ASSERT_TRUE(PutText(**seed, kLibraries, "other", "c").ok());
  auto store = ArtifactStore::Open(dir.File("s"));
  ASSERT_TRUE(store.ok());
  ASSERT_TRUE(PutText(**store, kLibraries, "other", "mine").ok());
  auto imported = (*store)->ImportSeed(dir.File("seed"), kLibraries);
  ASSERT_TRUE(imported.ok()) << imported.status();
  ASSERT_EQ(imported->size(), 1u);
  EXPECT_EQ((*imported)[0].id, "bundled");
  EXPECT_EQ((*imported)[0].version, 2u);
  EXPECT_EQ(Slurp(dir.File("s/libraries/bundled/2/data.txt")), "b");
  EXPECT_EQ(Slurp(dir.File("s/libraries/other/1/data.txt")), "mine");
  auto none = (*store)->ImportSeed(dir.File("seed"), kLibraries);
  ASSERT_TRUE(none.ok());
  EXPECT_TRUE(none->empty());
  auto missing = (*store)->ImportSeed(dir.File("no-such-seed"), kLibraries);
  ASSERT_TRUE(missing.ok());
  EXPECT_TRUE(missing->empty());
}

// A seed rebuilt by a newer kinemo (same ids, same version 1, other
// content) replaces what an older seed put in the store, never what was
// pushed.
TEST(ArtifactStore, ANewerSeedReplacesTheOlderSeedsArtifactsOnly) {
  testing::TempDir dir;
  auto old_seed = ArtifactStore::Open(dir.File("seed-old"));
  ASSERT_TRUE(old_seed.ok());
  ASSERT_TRUE(PutText(**old_seed, kControllers, "bundled", "old").ok());
  ASSERT_TRUE(PutText(**old_seed, kControllers, "pushed", "seed").ok());
  auto store = ArtifactStore::Open(dir.File("s"));
  ASSERT_TRUE(store.ok());
  auto first = (*store)->ImportSeed(dir.File("seed-old"), kControllers);
  ASSERT_TRUE(first.ok()) << first.status();
  ASSERT_EQ(first->size(), 2u);
  EXPECT_TRUE((*store)->Get(kControllers, "bundled")->seeded);
  // Someone pushes a version of their own over one seeded id.
  ASSERT_TRUE(PutText(**store, kControllers, "pushed", "mine", true).ok());
  EXPECT_FALSE((*store)->Get(kControllers, "pushed")->seeded);

  // The upgrade: a new seed, each id again at version 1, with new content.
  auto new_seed = ArtifactStore::Open(dir.File("seed-new"));
  ASSERT_TRUE(new_seed.ok());
  ASSERT_TRUE(PutText(**new_seed, kControllers, "bundled", "new, longer").ok());
  ASSERT_TRUE(PutText(**new_seed, kControllers, "pushed", "seed 2").ok());
  auto refreshed = (*store)->ImportSeed(dir.File("seed-new"), kControllers);
  ASSERT_TRUE(refreshed.ok()) << refreshed.status();
  ASSERT_EQ(refreshed->size(), 1u);
  EXPECT_EQ((*refreshed)[0].id, "bundled");
  EXPECT_EQ((*refreshed)[0].version, 1u);
  EXPECT_EQ(Slurp(dir.File("s/controllers/bundled/1/data.txt")), "new, longer");
  EXPECT_EQ((*store)->List(kControllers, "bundled", true)->size(), 1u);
  EXPECT_EQ(Slurp(dir.File("s/controllers/pushed/2/data.txt")), "mine");
  // The same seed again changes nothing.
  auto again = (*store)->ImportSeed(dir.File("seed-new"), kControllers);
  ASSERT_TRUE(again.ok());
  EXPECT_TRUE(again->empty());
  // A newer seed version is added beside the stored one.
  ASSERT_TRUE(PutText(**new_seed, kControllers, "bundled", "v2", true).ok());
  auto added = (*store)->ImportSeed(dir.File("seed-new"), kControllers);
  ASSERT_TRUE(added.ok());
  ASSERT_EQ(added->size(), 1u);
  EXPECT_EQ((*added)[0].version, 2u);
  EXPECT_EQ(Slurp(dir.File("s/controllers/bundled/1/data.txt")), "new, longer");
  EXPECT_EQ(Slurp(dir.File("s/controllers/bundled/2/data.txt")), "v2");
}

// Stores written before the "seeded" mark: a version with the seed's
// version number and description is the seed's; one with a description of
// its own is not.
TEST(ArtifactStore, UnmarkedVersionsCountAsSeededOnlyWithTheSeedsDescription) {
  testing::TempDir dir;
  auto store = ArtifactStore::Open(dir.File("s"));
  ASSERT_TRUE(store.ok());
  ASSERT_TRUE(PutText(**store, kLibraries, "bundled", "abc").ok());  // description "text abc"
  ASSERT_TRUE(PutText(**store, kLibraries, "mine", "abc").ok());
  auto seed = ArtifactStore::Open(dir.File("seed"));
  ASSERT_TRUE(seed.ok());
  {
    auto d = (*seed)->Begin(kLibraries, "bundled");
    ASSERT_TRUE(d.ok());
    ASSERT_TRUE(d->WriteFile("data.txt", "abcdef").ok());
    ArtifactMeta meta;
    meta.description = "text abc";  // as the old seed described it
    ASSERT_TRUE((*seed)->Commit(*std::move(d), meta, false).ok());
  }
  ASSERT_TRUE(PutText(**seed, kLibraries, "mine", "seed's own").ok());
  auto imported = (*store)->ImportSeed(dir.File("seed"), kLibraries);
  ASSERT_TRUE(imported.ok()) << imported.status();
  ASSERT_EQ(imported->size(), 1u);
  EXPECT_EQ((*imported)[0].id, "bundled");
  EXPECT_EQ(Slurp(dir.File("s/libraries/bundled/1/data.txt")), "abcdef");
  EXPECT_EQ(Slurp(dir.File("s/libraries/mine/1/data.txt")), "abc");
}

TEST(ArtifactStore, BadIdsAndFileNamesAreRefusedNamingTheField) {
  testing::TempDir dir;
  auto store = ArtifactStore::Open(dir.File("s"));
  ASSERT_TRUE(store.ok());
  auto bad_id = (*store)->Begin(kModels, "Has Space");
  EXPECT_EQ(bad_id.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_TRUE(absl::StartsWith(bad_id.status().message(), "id: ")) << bad_id.status();
  auto d = (*store)->Begin(kModels, "ok");
  ASSERT_TRUE(d.ok());
  for (const char* name : {"../escape", "/abs", ".hidden", "a//b", "artifact.json", "sp ace", ""}) {
    EXPECT_EQ(d->WriteFile(name, "x").code(), absl::StatusCode::kInvalidArgument) << name;
  }
  EXPECT_TRUE(d->WriteFile("clips/a.bvh", "x").ok());
  EXPECT_TRUE(ValidateFileName("dataset-1_bye_normal_001.bvh", "f").ok());
}

// Found by tests/fuzz/artifact_meta_fuzz (corpus: regression-created_unix_ms-1e128):
// numbers out of their field's range were cast (undefined behaviour); they
// are an error naming the field, as are floats where integers belong.
TEST(ArtifactStore, MetaNumbersOutOfRangeAreRefusedNamingTheField) {
  const struct {
    const char* json;
    const char* field;
  } cases[] = {
      {R"({"kind":"models","id":"m","version":1,"created_unix_ms":1.794e128})", "created_unix_ms"},
      {R"({"kind":"models","id":"m","version":4294967296})", "version"},
      {R"({"kind":"models","id":"m","version":-1})", "version"},
      {R"({"kind":"models","id":"m","version":1.5})", "version"},
      {R"({"kind":"models","id":"m","version":1,"files":[{"name":"a","size_bytes":-3}]})",
       "files[0].size_bytes"},
      {R"({"kind":"models","id":"m","version":1,"files":[{"name":"a","size_bytes":1e30}]})",
       "files[0].size_bytes"},
      {R"({"kind":"models","id":"m","version":1,"depends_on":[{"kind":"l","id":"x","version":9e9}]})",
       "depends_on[0].version"},
  };
  for (const auto& c : cases) {
    auto meta = MetaFromJson(c.json, "models/m/1");
    ASSERT_FALSE(meta.ok()) << c.json;
    EXPECT_EQ(meta.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_TRUE(
        absl::StartsWith(meta.status().message(), kinemo::StrCat("models/m/1: ", c.field, ": ")))
        << meta.status();
  }
  auto ok = MetaFromJson(
      R"({"kind":"models","id":"m","version":4294967295,"created_unix_ms":-9223372036854775808,)"
      R"("files":[{"name":"a","size_bytes":18446744073709551615}]})",
      "models/m/1");
  ASSERT_TRUE(ok.ok()) << ok.status();
  EXPECT_EQ(ok->version, 4294967295u);
  EXPECT_EQ(ok->created_unix_ms, std::numeric_limits<std::int64_t>::min());
  EXPECT_EQ(ok->files[0].size_bytes, std::numeric_limits<std::uint64_t>::max());
}

TEST(ArtifactStore, UnwritableRootIsAPreconditionNamingTheField) {
  testing::TempDir dir;
  std::ofstream(dir.File("file")) << "x";
  auto store = ArtifactStore::Open(dir.File("file/sub"), "planner.store_dir");
  EXPECT_EQ(store.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_TRUE(absl::StartsWith(store.status().message(), "planner.store_dir: ")) << store.status();
}

}  // namespace
}  // namespace kinemo::store
