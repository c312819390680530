#include "common/grpc/status_mapping.h"

#include <gtest/gtest.h>

namespace kinemo {
namespace {

TEST(StatusMapping, OkMapsToOk) { EXPECT_TRUE(ToGrpcStatus(absl::OkStatus()).ok()); }

TEST(StatusMapping, EveryCanonicalCodeKeepsItsMeaning) {
  const std::pair<absl::Status, grpc::StatusCode> cases[] = {
      {absl::InvalidArgumentError("x"), grpc::StatusCode::INVALID_ARGUMENT},
      {absl::NotFoundError("x"), grpc::StatusCode::NOT_FOUND},
      {absl::UnavailableError("x"), grpc::StatusCode::UNAVAILABLE},
      {absl::DeadlineExceededError("x"), grpc::StatusCode::DEADLINE_EXCEEDED},
      {absl::FailedPreconditionError("x"), grpc::StatusCode::FAILED_PRECONDITION},
      {absl::ResourceExhaustedError("x"), grpc::StatusCode::RESOURCE_EXHAUSTED},
      {absl::InternalError("x"), grpc::StatusCode::INTERNAL},
      {absl::CancelledError("x"), grpc::StatusCode::CANCELLED},
      {absl::AlreadyExistsError("x"), grpc::StatusCode::ALREADY_EXISTS},
      {absl::PermissionDeniedError("x"), grpc::StatusCode::PERMISSION_DENIED},
      {absl::AbortedError("x"), grpc::StatusCode::ABORTED},
      {absl::OutOfRangeError("x"), grpc::StatusCode::OUT_OF_RANGE},
      {absl::UnimplementedError("x"), grpc::StatusCode::UNIMPLEMENTED},
      {absl::DataLossError("x"), grpc::StatusCode::DATA_LOSS},
      {absl::UnauthenticatedError("x"), grpc::StatusCode::UNAUTHENTICATED},
      {absl::UnknownError("x"), grpc::StatusCode::UNKNOWN},
  };
  for (const auto& [in, code] : cases) {
    const grpc::Status out = ToGrpcStatus(in);
    EXPECT_EQ(out.error_code(), code) << in;
    EXPECT_EQ(out.error_message(), "x");
    // And back again.
    EXPECT_EQ(FromGrpcStatus(out).code(), in.code());
  }
}

TEST(StatusMapping, MessageNamingTheFieldIsKept) {
  const Status s = InvalidField("audio.sample_rate_hz", "0 is not supported");
  const grpc::Status g = ToGrpcStatus(s);
  EXPECT_EQ(g.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(g.error_message(), "audio.sample_rate_hz: 0 is not supported");
}

TEST(StatusMapping, LongMessagesAreCappedAtAUtf8Boundary) {
  std::string long_message;
  for (int i = 0; i < 2000; ++i) long_message += "\xC3\xA9";  // é, 2 bytes each
  const grpc::Status g = ToGrpcStatus(absl::InternalError(long_message));
  ASSERT_LE(g.error_message().size(), kMaxStatusMessageBytes);
  // Ends with the ellipsis, and what precedes it is whole é characters.
  const std::string& m = g.error_message();
  ASSERT_GE(m.size(), 3u);
  EXPECT_EQ(m.substr(m.size() - 3), "\xE2\x80\xA6");
  EXPECT_EQ((m.size() - 3) % 2, 0u);
}

TEST(StatusMapping, ShortMessagesAreUntouched) {
  EXPECT_EQ(CapMessage("abc", 10), "abc");
  EXPECT_EQ(CapMessage("abcdefghij", 10), "abcdefghij");
  EXPECT_EQ(CapMessage("abcdefghijk", 10), "abcdefg\xE2\x80\xA6");
}

TEST(StatusMapping, PeerPrefixOnTheWayBack) {
  const Status s = FromGrpcStatus(grpc::Status(grpc::StatusCode::UNAVAILABLE, "connect failed"),
                                  "robot_bridge");
  EXPECT_EQ(s.code(), absl::StatusCode::kUnavailable);
  EXPECT_EQ(s.message(), "robot_bridge: connect failed");
}

}  // namespace
}  // namespace kinemo
