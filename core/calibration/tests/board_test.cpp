// Board detection: chessboards on renders (corners against their true projections, the 180
// degree ambiguity resolved by colour), ChArUco on a drawn board warped by a known homography.
#include "cell/calibration/board.hpp"

#include <cmath>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/aruco/charuco.hpp>
#include <opencv2/imgproc.hpp>

#include "cell/testing/matchers.hpp"
#include "sim_views.hpp"

namespace cell::calibration {
namespace {

using ::cell::testing::IsErrWith;
using ::cell::testing::IsOk;

constexpr double kCornerTolPx = 0.15;

BoardSpec spec96() {
  BoardSpec b;
  b.columns = 9;
  b.rows = 6;
  b.square_mm = 10.0;
  return b;
}

cv::Mat render_board(const render::CameraModel& camera, const BoardSpec& spec,
                     const Eigen::Isometry3d& camera_T_board) {
  render::Scene scene;
  scene.table_height_mm = -5000.0;
  scene.lights.fluorescent_on = false;
  scene.targets.push_back(testing::chessboard_target(spec, camera_T_board));
  render::Lighting lighting;
  lighting.ambient = 0.8;
  return testing::render_view(camera, lighting, scene, Eigen::Isometry3d::Identity(), 1.0, 4);
}

// Every corner id lands on its own corner's projection, whichever way the board is turned in
// the image (OpenCV orders the corners from whichever end it likes).
TEST(Board, ChessboardCornersCarryTheirIdsAtAnyTurn) {
  const render::CameraDescription eye = testing::camera_file("ibm7545_eye.yaml");
  const BoardSpec spec = spec96();
  for (double roll : {0.0, 1.2, 3.0, 3.3, -2.0}) {
    const Eigen::Isometry3d camera_T_board =
        testing::board_facing_camera(spec, {2.0, -3.0, 420.0}, roll, 0.25, -0.15);
    const cv::Mat image = render_board(eye.truth.model, spec, camera_T_board);
    auto obs = detect_board(image, spec);
    ASSERT_THAT(obs, IsOk()) << "roll " << roll;
    ASSERT_EQ(obs->size(), 54U);
    double worst = 0.0;
    for (std::size_t k = 0; k < obs->size(); ++k) {
      EXPECT_EQ(obs->ids[k], static_cast<int>(k));
      auto px = eye.truth.model.project(camera_T_board * obs->object_points[k]);
      ASSERT_TRUE(px);
      worst = std::max(worst, (*px - obs->image_points[k]).norm());
    }
    EXPECT_LT(worst, kCornerTolPx) << "roll " << roll;
  }
}

TEST(Board, NoBoardAndBadInputAreClearErrors) {
  const cv::Mat blank(484, 512, CV_8UC1, cv::Scalar(120));
  EXPECT_THAT(detect_board(blank, spec96()),
              IsErrWith(Errc::kOutOfRange, "no chessboard 9x6 inner corners, 10 mm squares found"));
  EXPECT_THAT(detect_board(cv::Mat(), spec96()), IsErrWith(Errc::kInvalidArgument, "8-bit grey"));
  BoardSpec bad = spec96();
  bad.square_mm = 0.0;
  EXPECT_THAT(detect_board(blank, bad), IsErrWith(Errc::kInvalidArgument, "square_mm must be > 0"));
  BoardSpec size;
  EXPECT_THAT(parse_board_size("9x6", size), IsOk());
  EXPECT_EQ(size.columns, 9);
  EXPECT_EQ(size.rows, 6);
  EXPECT_THAT(parse_board_size("9by6", size), IsErrWith(Errc::kInvalidArgument, "'9by6'"));
  EXPECT_THAT(parse_board_size("1x6", size), IsErrWith(Errc::kInvalidArgument, "2..64"));
  BoardSpec symmetric;
  symmetric.columns = 8;
  symmetric.rows = 6;
  EXPECT_TRUE(symmetric.is_symmetric());
  EXPECT_FALSE(spec96().is_symmetric());
}

// ChArUco (OpenCV contrib's aruco, Debian's libopencv-contrib-dev): a board drawn flat, then
// the same image warped by a known homography: every corner id moves as the homography says.
TEST(Board, CharucoCornersFollowAKnownHomography) {
  BoardSpec spec;
  spec.kind = BoardKind::kCharuco;
  spec.columns = 6;
  spec.rows = 4;
  spec.square_mm = 30.0;
  spec.marker_mm = 22.0;
  spec.dictionary = "DICT_4X4_50";
  ASSERT_THAT(spec.validate(), IsOk());
  auto dictionary = cv::aruco::getPredefinedDictionary(cv::aruco::DICT_4X4_50);
  auto board = cv::aruco::CharucoBoard::create(7, 5, 30.0F, 22.0F, dictionary);
  cv::Mat flat;
  board->draw(cv::Size(700, 500), flat, 20, 1);
  auto a = detect_board(flat, spec);
  ASSERT_THAT(a, IsOk());
  EXPECT_GE(a->size(), 20U);
  cv::Mat h = (cv::Mat_<double>(3, 3) << 0.9, 0.12, 40.0, -0.08, 0.85, 60.0, 0.0001, 0.00015, 1.0);
  cv::Mat warped;
  cv::warpPerspective(flat, warped, h, cv::Size(820, 640), cv::INTER_CUBIC, cv::BORDER_CONSTANT,
                      cv::Scalar(255));
  auto b = detect_board(warped, spec);
  ASSERT_THAT(b, IsOk());
  std::size_t matched = 0;
  for (std::size_t i = 0; i < a->size(); ++i) {
    for (std::size_t j = 0; j < b->size(); ++j) {
      if (a->ids[i] != b->ids[j]) {
        continue;
      }
      const Eigen::Vector2d p = a->image_points[i];
      const double w = h.at<double>(2, 0) * p.x() + h.at<double>(2, 1) * p.y() + h.at<double>(2, 2);
      const Eigen::Vector2d q((h.at<double>(0, 0) * p.x() + h.at<double>(0, 1) * p.y() + h.at<double>(0, 2)) / w,
                              (h.at<double>(1, 0) * p.x() + h.at<double>(1, 1) * p.y() + h.at<double>(1, 2)) / w);
      EXPECT_LT((q - b->image_points[j]).norm(), 0.3) << "id " << a->ids[i];
      EXPECT_EQ(a->object_points[i], b->object_points[j]);
      ++matched;
    }
  }
  EXPECT_GE(matched, 18U);
}

}  // namespace
}  // namespace cell::calibration
