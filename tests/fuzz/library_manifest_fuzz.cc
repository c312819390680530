// Fuzzes library manifests (services/planner/library): the input is a
// manifest.json in a folder that holds real clips (the BVH seeds of
// corpus/bvh: a Bandai take, a 100-joint CMU export, the 31-joint CMU 131
// skeleton, at 30, 60 and 120 fps), loaded with LoadLibrary as `kinemo
// library push` and LoadLibrary requests do; phrase annotations are then
// checked as a push checks them (gesture::ExtractPhrases).
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include "services/planner/gesture/phrases.h"
#include "services/planner/library/library.h"
#include "tests/fuzz/fuzz_check.h"

namespace {

namespace fs = std::filesystem;

constexpr const char* kClips[] = {"dataset-1_bye_normal_001.bvh", "cmu_007_12.bvh",
                                  "cmu_131_01.bvh"};

// A private folder with the clips, removed at exit.
const fs::path& Folder() {
  static const fs::path dir = [] {
    std::string tmpl = (fs::temp_directory_path() / "kinemo-library-fuzz-XXXXXX").string();
    if (mkdtemp(tmpl.data()) == nullptr) std::abort();
    for (const char* clip : kClips) {
      fs::copy_file(fs::path(KINEMO_FUZZ_CORPUS_DIR) / "bvh" / clip, fs::path(tmpl) / clip);
    }
    std::atexit([] { fs::remove_all(Folder()); });
    return fs::path(tmpl);
  }();
  return dir;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const fs::path manifest = Folder() / "manifest.json";
  {
    std::ofstream out(manifest, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
    if (!out.flush()) std::abort();  // the harness itself failed
  }
  kinemo::planner::LibrarySources sources;
  sources.paths = {manifest.string()};
  sources.max_clips = 64;
  auto library = kinemo::planner::LoadLibrary("fuzz", sources);
  if (!library.ok()) {
    // Bad manifests are INVALID_ARGUMENT; a clip path naming nothing is NOT_FOUND.
    KINEMO_FUZZ_CHECK_REFUSED(library.status(), absl::StatusCode::kInvalidArgument,
                              absl::StatusCode::kNotFound, absl::StatusCode::kResourceExhausted);
    return 0;
  }
  const auto& lib = **library;
  KINEMO_FUZZ_CHECK(!lib.clips.empty() && lib.frame_rate_hz > 0 && lib.meters_per_unit > 0,
                    "a library without clips, rate or scale");
  for (const auto& clip : lib.clips) {
    KINEMO_FUZZ_CHECK(clip.clip.skeleton.num_channels() == lib.skeleton.num_channels(),
                      clip.name + ": not on the library's skeleton");
    KINEMO_FUZZ_CHECK(clip.clip.Validate().ok(), clip.clip.Validate().ToString());
  }
  (void)lib.tones();
  (void)lib.keywords();
  // As a push does: annotations are checked when a clip has one.
  bool annotated = false;
  for (const auto& clip : lib.clips) annotated = annotated || !clip.annotation_json.empty();
  if (!annotated) return 0;
  auto phrases = kinemo::planner::gesture::ExtractPhrases(lib);
  if (!phrases.ok()) {
    KINEMO_FUZZ_CHECK_REFUSED(phrases.status(), absl::StatusCode::kInvalidArgument,
                              absl::StatusCode::kFailedPrecondition,
                              absl::StatusCode::kResourceExhausted);
  }
  return 0;
}
