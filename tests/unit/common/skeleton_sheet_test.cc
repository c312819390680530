#include "common/image/skeleton_sheet.h"

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "common/motion/bvh.h"

namespace kinemo::image {
namespace {

cv::Mat Decode(const std::string& png) {
  std::vector<uchar> bytes(png.begin(), png.end());
  return cv::imdecode(bytes, cv::IMREAD_COLOR);
}

// Dark (figure) pixels inside one panel.
int InkIn(const cv::Mat& img, int col, int row, int px) {
  cv::Mat gray;
  cv::cvtColor(img(cv::Rect(col * px + 1, row * px + 20, px - 2, px - 21)), gray, cv::COLOR_BGR2GRAY);
  return cv::countNonZero(gray < 160);
}

TEST(SkeletonSheet, DrawsEveryPanelAndTheMotionShows) {
  auto clip = motion::ReadBvhFile(KINEMO_TEST_DATA_DIR "/motion/dataset-1_bye_normal_001.bvh");
  ASSERT_TRUE(clip.ok()) << clip.status();
  auto png = RenderSkeletonSheetPng(*clip, {.panels = 8, .columns = 4, .panel_px = 160});
  ASSERT_TRUE(png.ok()) << png.status();
  const cv::Mat img = Decode(*png);
  ASSERT_EQ(img.cols, 4 * 160);
  ASSERT_EQ(img.rows, 2 * 160);
  for (int i = 0; i < 8; ++i) EXPECT_GT(InkIn(img, i % 4, i / 4, 160), 150) << "panel " << i;
  // The wave: the first panel (rest) and the second (hand raised) differ.
  cv::Mat a = img(cv::Rect(0, 20, 160, 140)), b = img(cv::Rect(160, 20, 160, 140)), diff;
  cv::absdiff(a, b, diff);
  cv::cvtColor(diff, diff, cv::COLOR_BGR2GRAY);
  EXPECT_GT(cv::countNonZero(diff > 60), 40);
}

TEST(SkeletonSheet, RejectsBadOptions) {
  auto clip = motion::ReadBvhFile(KINEMO_TEST_DATA_DIR "/motion/dataset-1_bye_normal_001.bvh");
  ASSERT_TRUE(clip.ok());
  EXPECT_EQ(RenderSkeletonSheetPng(*clip, {.panels = 0}).status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(RenderSkeletonSheetPng(*clip, {.panel_px = 10}).status().code(), absl::StatusCode::kInvalidArgument);
  motion::Clip empty;
  EXPECT_EQ(RenderSkeletonSheetPng(empty).status().code(), absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace kinemo::image
