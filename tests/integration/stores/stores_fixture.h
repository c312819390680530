// Shared by the store integration tests: the built binaries, a small paired
// corpus from tests/data (real LibriVox speech and a real Bandai gesture clip,
// paired synthetically: they were not recorded together), a model file
// trained on it, and running the `kinemo` CLI.
#pragma once

#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "common/testing/process.h"
#include "services/inference/core/model_store.h"
#include "services/inference/corpus/corpus.h"

namespace kinemo::stores_test {

inline const std::string kData = KINEMO_TEST_DATA_DIR;

inline std::string Binary(const std::string& name) { return testing::FindBuiltBinary(KINEMO_BINARY_DIR, name); }

// The corpus, built under `dir`.
inline StatusOr<std::vector<inference::PairedSequence>> TinyCorpus(const std::string& dir) {
  inference::SyntheticCorpusOptions co;
  co.speech_files = {kData + "/speech/sense_and_sensibility_01_austen_64kb-0880.wav",
                     kData + "/speech/sense_and_sensibility_01_austen_64kb-0930.wav"};
  co.gesture_files = {kData + "/motion/dataset-1_bye_normal_001.bvh"};
  co.out_dir = dir;
  co.renditions = 2;
  KINEMO_RETURN_IF_ERROR(inference::BuildSyntheticCorpus(co).status());
  return inference::ImportPairedCorpus(dir);
}

// A small model (3 states, window 2) trained on `data`, written to `path`
// with `file_id` as the id inside the file.
inline Status WriteTinyModel(const std::vector<inference::PairedSequence>& data, const std::string& path,
                             const std::string& file_id) {
  inference::ModelTrainParams p;
  p.num_states = 3;
  p.window = 2;
  p.num_clusters = 3;
  p.hmm_restarts = 1;
  inference::TrainReport report;
  KINEMO_ASSIGN_OR_RETURN(inference::RemappedModel model, inference::RemappedModel::Train(data, p, nullptr, &report));
  auto info = inference::MakeModelInfo(model, p, report, static_cast<std::uint32_t>(data.size()),
                                       "tests/data synthetic pairing");
  info.set_model_id(file_id);
  return inference::WriteModelFile(path, inference::EncodeModel(model, info));
}

// Runs the built tool TOOL (kinemo, kinemo-vision) with ARGS...; returns its
// exit code, with its stdout in *out and its stderr in *err.
inline int RunTool(const std::string& tool, const std::vector<std::string>& args, std::string* out,
                   std::string* err = nullptr) {
  const std::string binary = Binary(tool);
  testing::TempDir dir;
  std::string command = "'" + binary + "'";
  for (const auto& a : args) {
    std::string quoted;
    for (char c : a) quoted += c == '\'' ? std::string("'\\''") : std::string(1, c);
    command += " '" + quoted + "'";
  }
  command += " 2>'" + dir.File("stderr") + "'";
  FILE* p = ::popen(command.c_str(), "r");
  if (p == nullptr) return -1;
  std::array<char, 4096> buf;
  out->clear();
  std::size_t n;
  while ((n = std::fread(buf.data(), 1, buf.size(), p)) > 0) out->append(buf.data(), n);
  const int status = ::pclose(p);
  std::ifstream e(dir.File("stderr"));
  std::stringstream ss;
  ss << e.rdbuf();
  if (err != nullptr) *err = ss.str();
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

// Runs `kinemo ARGS...` (RunTool).
inline int RunKinemo(const std::vector<std::string>& args, std::string* out, std::string* err = nullptr) {
  return RunTool("kinemo", args, out, err);
}

}  // namespace kinemo::stores_test
