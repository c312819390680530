// Starts the real `prosody` binary on an ephemeral loopback port (harness)
// and analyses real LibriVox speech over gRPC.
#include <chrono>
#include <fstream>
#include <sstream>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "common/testing/process.h"
#include "kinemo/prosody/v1/prosody.grpc.pb.h"

namespace kinemo::prosody {
namespace {

TEST(ProsodyBinaryTest, AnalyzesSpeechAndStopsCleanly) {
  const std::string binary = kinemo::testing::FindBuiltBinary(KINEMO_BINARY_DIR, "prosody");
  ASSERT_FALSE(binary.empty()) << "prosody binary not built";
  kinemo::testing::TempDir dir;
  {
    std::ofstream cfg(dir.File("prosody.textproto"));
    cfg << "max_audio_s: 30\nrecognizer { disabled: true }\n";
  }
  auto svc = kinemo::testing::ServiceProcess::Start(
      {.binary = binary, .args = {"--config", dir.File("prosody.textproto")}});
  ASSERT_TRUE(svc.ok()) << svc.status();
  auto stub = v1::ProsodyService::NewStub((*svc)->Channel());
  std::ifstream in(std::string(KINEMO_TEST_DATA_DIR) +
                       "/speech/sense_and_sensibility_01_austen_64kb-0930.wav",
                   std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  v1::AnalyzeRequest request;
  request.mutable_audio()->mutable_format()->set_encoding(common::v1::AUDIO_ENCODING_FILE);
  request.mutable_audio()->set_data(ss.str());
  request.set_omit_frames(true);
  v1::AnalyzeResponse response;
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
  const grpc::Status status = stub->Analyze(&ctx, request, &response);
  ASSERT_TRUE(status.ok()) << status.error_message();
  EXPECT_EQ(response.track().frames_size(), 0);
  EXPECT_GT(response.track().syllables_size(), 5);
  EXPECT_GT(response.track().accents_size(), 0);
  auto code = (*svc)->Stop();
  ASSERT_TRUE(code.ok()) << code.status();
  EXPECT_EQ(*code, 0);
}

}  // namespace
}  // namespace kinemo::prosody
