// Fuzzes the artifact store's reader of artifact.json (common/store
// MetaFromJson): every service reads these at start, and a copied or damaged
// store folder must not crash it. Accepted metadata must write and read back
// to the same metadata (MetaToJson, as Commit writes it).
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "common/store/artifact_store.h"
#include "tests/fuzz/fuzz_check.h"

namespace {

bool SameMeta(const kinemo::store::ArtifactMeta& a, const kinemo::store::ArtifactMeta& b) {
  if (a.kind != b.kind || a.id != b.id || a.version != b.version ||
      a.created_unix_ms != b.created_unix_ms || a.description != b.description ||
      a.files.size() != b.files.size() || a.depends_on != b.depends_on ||
      a.summary_json != b.summary_json) {
    return false;
  }
  for (size_t i = 0; i < a.files.size(); ++i) {
    if (a.files[i].name != b.files[i].name || a.files[i].size_bytes != b.files[i].size_bytes)
      return false;
  }
  return true;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view text = kinemo::fuzz::Text(data, size);
  auto meta = kinemo::store::MetaFromJson(text, "models/fuzz/1");
  if (!meta.ok()) {
    KINEMO_FUZZ_CHECK_REFUSED(meta.status(), absl::StatusCode::kInvalidArgument);
    return 0;
  }
  KINEMO_FUZZ_CHECK(kinemo::store::IsValidId(meta->kind) && kinemo::store::IsValidId(meta->id) &&
                        meta->version > 0,
                    "accepted an invalid reference");
  (void)meta->size_bytes();
  (void)kinemo::store::RefString(meta->ref());
  auto again = kinemo::store::MetaFromJson(kinemo::store::MetaToJson(*meta), "rewritten");
  KINEMO_FUZZ_CHECK(again.ok(), again.status().ToString());
  KINEMO_FUZZ_CHECK(SameMeta(*meta, *again), "write → read changed the metadata");
  return 0;
}
