// Fuzzes the validation of a PushArtifact header (common/grpc/artifact_rpcs
// ValidatePushHeader): the input is the serialized header as it comes off
// the wire, validated against every kind the all-in-one's store holds. An
// accepted header's files must be valid, distinct names that stay inside
// the draft folder, and within the size limit.
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <set>
#include <string>
#include <vector>

#include "common/grpc/artifact_rpcs.h"
#include "tests/fuzz/fuzz_check.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  kinemo::common::v1::PushArtifactHeader header;
  if (!header.ParseFromArray(data, static_cast<int>(size))) return 0;
  static const std::vector<std::string> kKinds = {
      "models", "libraries", "controllers", "gesture_graphs", "locomotion_graphs", "cubes"};
  constexpr uint64_t kMaxBytes = 64u << 20;
  const auto s = kinemo::ValidatePushHeader(header, kKinds, kMaxBytes);
  if (!s.ok()) {
    KINEMO_FUZZ_CHECK_REFUSED(s, absl::StatusCode::kInvalidArgument,
                              absl::StatusCode::kResourceExhausted);
    KINEMO_FUZZ_CHECK(s.message().rfind("header.", 0) == 0,
                      "the message does not name a header field: " + s.ToString());
    return 0;
  }
  const std::filesystem::path draft = "/store/.staging/draft";
  std::set<std::string> names;
  uint64_t total = 0;
  for (const auto& f : header.files()) {
    KINEMO_FUZZ_CHECK(kinemo::store::ValidateFileName(f.name(), "name").ok(), f.name());
    KINEMO_FUZZ_CHECK(names.insert(f.name()).second, "duplicate file name accepted: " + f.name());
    const std::filesystem::path path = (draft / f.name()).lexically_normal();
    const auto rel = path.lexically_relative(draft);
    KINEMO_FUZZ_CHECK(!rel.empty() && *rel.begin() != ".." && *rel.begin() != ".",
                      "escapes the draft: " + f.name());
    KINEMO_FUZZ_CHECK(f.size_bytes() <= kMaxBytes - total, "over the size limit");
    total += f.size_bytes();
  }
  return 0;
}
