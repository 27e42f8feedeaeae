// Images from the bus and from files: every malformation named, nothing crashes.
#include "cell/vision/image.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <vector>

#include "cell/testing/matchers.hpp"

namespace cell::vision {
namespace {

using ::cell::testing::IsErr;
using ::cell::testing::IsErrWith;
using ::cell::testing::IsOk;

std::vector<std::uint8_t> ramp(std::size_t n) {
  std::vector<std::uint8_t> v(n);
  for (std::size_t i = 0; i < n; ++i) {
    v[i] = static_cast<std::uint8_t>(i * 7);
  }
  return v;
}

TEST(ImageFromRaw, CopiesMonoRowsWithTheirStep) {
  const auto data = ramp(std::size_t{4} * 10);  // 3 rows of 8 px with a step of 10
  const auto m = image_from_raw(8, 3, 10, "mono8", std::span(data).first(28));
  ASSERT_THAT(m, IsOk());
  EXPECT_EQ(m->cols, 8);
  EXPECT_EQ(m->rows, 3);
  EXPECT_TRUE(m->isContinuous());
  EXPECT_EQ(m->at<std::uint8_t>(1, 0), data[10]);
  EXPECT_EQ(m->at<std::uint8_t>(2, 7), data[27]);
}

TEST(ImageFromRaw, ConvertsRgbToGrey) {
  std::vector<std::uint8_t> rgb = {255, 0, 0, 0, 255, 0};
  const auto m = image_from_raw(2, 1, 6, "rgb8", rgb);
  ASSERT_THAT(m, IsOk());
  EXPECT_EQ(m->at<std::uint8_t>(0, 0), 76);   // 0.299 * 255
  EXPECT_EQ(m->at<std::uint8_t>(0, 1), 150);  // 0.587 * 255
}

TEST(ImageFromRaw, NamesEveryMalformation) {
  const auto data = ramp(1000);
  EXPECT_THAT(image_from_raw(512, 484, 512, "mono8", data),
              IsErrWith(Errc::kInvalidArgument, "truncated: 1000 of 247808 bytes"));
  EXPECT_THAT(image_from_raw(0, 10, 10, "mono8", data),
              IsErrWith(Errc::kInvalidArgument, "0 x 10 px is not in 1..16384"));
  EXPECT_THAT(image_from_raw(10, 10, 10, "bayer_rggb8", data),
              IsErrWith(Errc::kInvalidArgument, "encoding 'bayer_rggb8' is not supported"));
  EXPECT_THAT(image_from_raw(10, 10, 20, "rgb8", data),
              IsErrWith(Errc::kInvalidArgument, "step 20 bytes is less than a rgb8 row's 30"));
  EXPECT_THAT(image_from_raw(10, 10, 10, "mono8", {}),
              IsErrWith(Errc::kInvalidArgument, "truncated"));
}

class ImageFileTest : public ::testing::Test {
 protected:
  ImageFileTest() {
    std::string pattern = "/tmp/cell-vision-image-XXXXXX";
    dir_ = mkdtemp(pattern.data()) != nullptr ? pattern : "/tmp";
  }
  ~ImageFileTest() override {
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }
  std::string write(const std::string& name, const std::vector<std::uint8_t>& bytes) {
    std::string path = dir_ + "/" + name;
    std::ofstream(path, std::ios::binary)
        .write(reinterpret_cast<const char*>(bytes.data()),
               static_cast<std::streamsize>(bytes.size()));
    return path;
  }
  static std::vector<std::uint8_t> encoded(const std::string& ext, int depth = CV_8U) {
    cv::Mat m(40, 60, CV_MAKETYPE(depth, 1));
    cv::randu(m, 0, depth == CV_8U ? 255 : 65535);
    std::vector<std::uint8_t> out;
    cv::imencode(ext, m, out);
    return out;
  }
  std::string dir_;
};

TEST_F(ImageFileTest, ReadsPngJpegPgmAndSixteenBitPng) {
  for (const std::string ext : {".png", ".jpg", ".pgm", ".bmp", ".tif"}) {
    const auto m = load_image_file(write("a" + ext, encoded(ext)));
    ASSERT_THAT(m, IsOk()) << ext;
    EXPECT_EQ(m->type(), CV_8UC1);
    EXPECT_EQ(m->cols, 60);
  }
  const auto deep = load_image_file(write("deep.png", encoded(".png", CV_16U)));
  ASSERT_THAT(deep, IsOk());
  EXPECT_EQ(deep->type(), CV_8UC1);
}

TEST_F(ImageFileTest, EmptyTruncatedAndNonImageFilesGiveClearErrors) {
  const auto missing = load_image_file(dir_ + "/nope.png");
  EXPECT_THAT(missing, IsErrWith(Errc::kIo, "cannot open"));
  EXPECT_THAT(missing.error().message, ::testing::HasSubstr("nope.png"));
  EXPECT_THAT(load_image_file(write("empty.png", {})),
              IsErrWith(Errc::kInvalidArgument, "empty file (0 bytes)"));
  auto png = encoded(".png");
  png.resize(png.size() / 2);
  EXPECT_THAT(load_image_file(write("half.png", png)),
              IsErrWith(Errc::kInvalidArgument, "truncated PNG"));
  auto jpg = encoded(".jpg");
  jpg.resize(jpg.size() - 40);
  EXPECT_THAT(load_image_file(write("half.jpg", jpg)),
              IsErrWith(Errc::kInvalidArgument, "truncated JPEG"));
  const std::string text = "not an image at all\n";
  EXPECT_THAT(load_image_file(write("notes.png", {text.begin(), text.end()})),
              IsErrWith(Errc::kInvalidArgument, "not an image"));
  EXPECT_THAT(load_image_file(dir_), IsErr(Errc::kIo));  // a directory
  // A PNG signature on garbage: the decoder cannot finish it.
  std::vector<std::uint8_t> fake = {0x89, 'P', 'N', 'G', 0x0D, 0x0A, 0x1A, 0x0A};
  fake.resize(64, 0x55);
  const std::uint8_t iend[] = {0, 0, 0, 0, 'I', 'E', 'N', 'D', 0xAE, 0x42, 0x60, 0x82};
  fake.insert(fake.end(), std::begin(iend), std::end(iend));
  EXPECT_THAT(load_image_file(write("fake.png", fake)),
              IsErrWith(Errc::kInvalidArgument, "cannot be decoded"));
}

}  // namespace
}  // namespace cell::vision
