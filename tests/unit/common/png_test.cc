#include "common/image/png.h"

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace kinemo::image {
namespace {

const std::string kImages = KINEMO_TEST_DATA_DIR "/images/";

cv::Mat Decode(const std::string& png, int flags) {
  std::vector<uchar> bytes(png.begin(), png.end());
  return cv::imdecode(bytes, flags);
}

TEST(Png, ColourPhotoRoundTripsExactlyThroughOpenCV) {
  cv::Mat photo = cv::imread(kImages + "fruits.jpg", cv::IMREAD_COLOR);
  ASSERT_FALSE(photo.empty());
  auto png = EncodePng({photo.data, photo.cols, photo.rows, 3, photo.step, true});
  ASSERT_TRUE(png.ok()) << png.status();
  cv::Mat back = Decode(*png, cv::IMREAD_UNCHANGED);
  ASSERT_EQ(back.type(), CV_8UC3);
  EXPECT_EQ(cv::norm(photo, back, cv::NORM_INF), 0.0);
}

TEST(Png, GrayAndAlphaAndRegionsOfInterest) {
  cv::Mat gray = cv::imread(kImages + "building.jpg", cv::IMREAD_GRAYSCALE);
  ASSERT_FALSE(gray.empty());
  cv::Mat roi = gray(cv::Rect(13, 7, 101, 57));  // stride != width
  auto png = EncodePng({roi.data, roi.cols, roi.rows, 1, roi.step, true});
  ASSERT_TRUE(png.ok()) << png.status();
  cv::Mat back = Decode(*png, cv::IMREAD_UNCHANGED);
  ASSERT_EQ(back.type(), CV_8UC1);
  EXPECT_EQ(cv::norm(roi, back, cv::NORM_INF), 0.0);

  cv::Mat colour = cv::imread(kImages + "home.jpg", cv::IMREAD_COLOR), bgra;
  cv::cvtColor(colour, bgra, cv::COLOR_BGR2BGRA);
  for (int y = 0; y < bgra.rows; ++y) bgra.at<cv::Vec4b>(y, y % bgra.cols)[3] = 17;
  auto png4 = EncodePng({bgra.data, bgra.cols, bgra.rows, 4, bgra.step, true});
  ASSERT_TRUE(png4.ok());
  cv::Mat back4 = Decode(*png4, cv::IMREAD_UNCHANGED);
  ASSERT_EQ(back4.type(), CV_8UC4);
  EXPECT_EQ(cv::norm(bgra, back4, cv::NORM_INF), 0.0);
}

TEST(Png, RejectsBadBuffersNamingTheField) {
  const std::uint8_t px[12] = {};
  EXPECT_NE(EncodePng({nullptr, 2, 2, 3, 0, true}).status().message().find("pixels.data"), std::string::npos);
  EXPECT_NE(EncodePng({px, 2, 2, 2, 0, true}).status().message().find("pixels.channels"), std::string::npos);
  EXPECT_NE(EncodePng({px, 2, 2, 3, 5, true}).status().message().find("pixels.stride"), std::string::npos);
  EXPECT_EQ(EncodePng({px, 0, 2, 3, 0, true}).status().code(), absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace kinemo::image
