// The checks every request gets (common/grpc/request_check.h), on real
// kinemo request types: paths with indexes, bytes that are no message,
// undefined enum numbers, NaN, uint32 values that do not fit an int.
#include "common/grpc/request_check.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "kinemo/common/v1/artifact.pb.h"
#include "kinemo/inference/v1/inference.pb.h"
#include "kinemo/prosody/v1/prosody.pb.h"

namespace kinemo {
namespace {

TEST(DescribeUnparseable, NamesTheStringWithInvalidUtf8ByItsPath) {
  common::v1::PushArtifactRequest request;
  auto* header = request.mutable_header();
  for (const char* name : {"a.bvh", "b.bvh", "c.bvh"}) header->add_files()->set_name(name);
  std::string bytes = request.SerializeAsString();
  const auto at = bytes.find("c.bvh");
  ASSERT_NE(at, std::string::npos);
  bytes[at] = '\xff';  // same length: the framing stays valid
  common::v1::PushArtifactRequest parsed;
  ASSERT_FALSE(parsed.ParseFromString(bytes));
  EXPECT_EQ(DescribeUnparseable(bytes, common::v1::PushArtifactRequest::descriptor()),
            "header.files[2].name: invalid UTF-8");
}

TEST(DescribeUnparseable, BytesThatAreNoMessage) {
  for (const std::string& bytes : {std::string("\xff\xff\xff"), std::string("\x0a\x05\x01", 3), std::string("\x07")}) {
    EXPECT_EQ(DescribeUnparseable(bytes, prosody::v1::AnalyzeRequest::descriptor()),
              "request: not a valid kinemo.prosody.v1.AnalyzeRequest message");
  }
}

TEST(CheckRequestValues, UndefinedEnumsAndNonFiniteNumbersNameTheField) {
  prosody::v1::AnalyzeRequest request;
  EXPECT_TRUE(CheckRequestValues(request).ok());
  request.mutable_audio()->mutable_format()->set_encoding(static_cast<common::v1::AudioEncoding>(9999));
  Status s = CheckRequestValues(request);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(s.message(), "audio.format.encoding: 9999 is not a defined AudioEncoding value");

  inference::v1::InferRequest infer;
  infer.add_inputs()->set_intensity_mean_db(60);
  infer.add_inputs()->set_intensity_mean_db(std::numeric_limits<double>::infinity());
  s = CheckRequestValues(infer, "config");
  EXPECT_EQ(s.message(), "config.inputs[1].intensity_mean_db: not a finite number");
  infer.mutable_inputs(1)->set_intensity_mean_db(std::nan(""));
  EXPECT_EQ(CheckRequestValues(infer).message(), "inputs[1].intensity_mean_db: not a finite number");
  infer.mutable_inputs(1)->set_intensity_mean_db(1e308);  // finite: bounds are the service's
  EXPECT_TRUE(CheckRequestValues(infer).ok());
}

TEST(CheckFitsInt, PrintsLargeValuesAsSent) {
  inference::v1::TrainParams params;
  params.set_num_states(25);
  EXPECT_TRUE(CheckFitsInt(params, "params").ok());
  params.set_window(4294967295u);
  EXPECT_EQ(CheckFitsInt(params, "params").message(), "params.window: 4294967295 is too large");
}

}  // namespace
}  // namespace kinemo
