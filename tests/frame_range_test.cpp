// Open Job Description frame ranges, as `submit --frames` takes them.
#include <gtest/gtest.h>

#include "farm/frame_range.h"

namespace rf {
namespace {

using V = std::vector<FrameNumber>;

TEST(FrameRange, Forms) {
  EXPECT_EQ(parse_frame_range("7"), V({7}));
  EXPECT_EQ(parse_frame_range("1-4"), V({1, 2, 3, 4}));
  EXPECT_EQ(parse_frame_range("1-10:2"), V({1, 3, 5, 7, 9}));
  EXPECT_EQ(parse_frame_range("1,3,7-9"), V({1, 3, 7, 8, 9}));
  EXPECT_EQ(parse_frame_range("10-1:-3"), V({10, 7, 4, 1}));
  EXPECT_EQ(parse_frame_range("5-2"), V({5, 4, 3, 2}));
  EXPECT_EQ(parse_frame_range(" 1 - 3 , 9 "), V({1, 2, 3, 9}));
  EXPECT_EQ(parse_frame_range("0-0"), V({0}));
}

// Negative frames (handles, pre-roll): a range's separator is the first '-' after its first
// character, so "-3" is one frame and "-3--1", "-2-2", "2--2:-2" are ranges.
TEST(FrameRange, NegativeFrames) {
  EXPECT_EQ(parse_frame_range("-3"), V({-3}));
  EXPECT_EQ(parse_frame_range("-3--1"), V({-3, -2, -1}));
  EXPECT_EQ(parse_frame_range("-2-2"), V({-2, -1, 0, 1, 2}));
  EXPECT_EQ(parse_frame_range("2--2:-2"), V({2, 0, -2}));
  EXPECT_EQ(parse_frame_range("-10--4:3,1"), V({-10, -7, -4, 1}));
  EXPECT_EQ(parse_frame_range("-2147483648"), V({INT32_MIN}));
  EXPECT_EQ(parse_frame_range("2147483646-2147483647"), V({INT32_MAX - 1, INT32_MAX}));
}

void expect_error(const std::string& text, const std::string& what) {
  try {
    parse_frame_range(text);
    ADD_FAILURE() << "accepted '" << text << "'";
  } catch (const FrameRangeError& e) {
    EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
  }
}

TEST(FrameRange, ErrorsSayWhichItemAndWhy) {
  expect_error("", "empty");
  expect_error("1,,3", "empty item");
  expect_error("1-x", "item '1-x': end 'x' is not an integer");
  expect_error("1-10:0", "step must not be 0");
  expect_error("1-10:-1", "goes away from the end");
  expect_error("-3--5:1", "goes away from the end");
  expect_error("--3", "item '--3': start '-' is not an integer");
  expect_error("-2147483649", "frame number out of range (-2147483648 to 2147483647)");
  expect_error("2147483647-2147483648", "out of range");
  expect_error("1-3,2", "frame 2 is listed twice");
  expect_error("4:2", "a step needs a range");
  expect_error("0-2000000", "more than 1000000 frames");
  expect_error("1-99999999999", "out of range");
}

TEST(ExpandFramePattern, PadsEachRunOfHashes) {
  EXPECT_EQ(expand_frame_pattern("shot.####.json", 7), "shot.0007.json");
  EXPECT_EQ(expand_frame_pattern("shot.####.json", 12345), "shot.12345.json");
  EXPECT_EQ(expand_frame_pattern("a#b##", 3), "a3b03");
  EXPECT_EQ(expand_frame_pattern("scene.json", 42), "scene.json");
  EXPECT_EQ(expand_frame_pattern("#", 0), "0");
  // A negative frame as printf's %04d writes it: the sign counts in the width.
  EXPECT_EQ(expand_frame_pattern("shot.####.json", -7), "shot.-007.json");
  EXPECT_EQ(expand_frame_pattern("shot.#.json", -7), "shot.-7.json");
  EXPECT_EQ(expand_frame_pattern("shot.####.json", -12345), "shot.-12345.json");
  EXPECT_EQ(expand_frame_pattern("s.####", INT32_MIN), "s.-2147483648");
  // Scene patterns take '#' only: a '%' in a bundle's file name stays as written.
  EXPECT_EQ(expand_frame_pattern("a%04d.json", 7), "a%04d.json");
}

// frame_range_text writes runs briefly, negative frames included, and parse_frame_range reads
// the text back as the sorted set.
TEST(FrameRange, TextOfASetReadsBack) {
  EXPECT_EQ(frame_range_text({}), "");
  EXPECT_EQ(frame_range_text({7}), "7");
  EXPECT_EQ(frame_range_text({5, 1, 2, 3, 4, 7, 9, 10, 12, 11, 3}), "1-5,7,9-12");
  EXPECT_EQ(frame_range_text({-1, -3, -2, 2}), "-3--1,2");
  EXPECT_EQ(frame_range_text({INT32_MAX, INT32_MIN}), "-2147483648,2147483647");
  for (std::vector<FrameNumber> set : {std::vector<FrameNumber>{-3, -2, -1, 2},
                                       std::vector<FrameNumber>{1, 2, 3, 4, 5, 7, 9, 10, 11, 12},
                                       std::vector<FrameNumber>{INT32_MIN, 0, INT32_MAX}})
    EXPECT_EQ(parse_frame_range(frame_range_text(set)), set);
}

// Output templates (render -o): '#' runs and printf's %d and %0Nd, %% a percent sign, any other
// '%' as written; is_frame_pattern says whether a name changes with the frame.
TEST(ExpandFramePattern, OutputTemplatesTakePrintfFields) {
  EXPECT_EQ(expand_frame_pattern("shot.%04d.exr", 7, true), "shot.0007.exr");
  EXPECT_EQ(expand_frame_pattern("shot.%d.exr", 7, true), "shot.7.exr");
  EXPECT_EQ(expand_frame_pattern("shot.%010d.exr", 42, true), "shot.0000000042.exr");
  EXPECT_EQ(expand_frame_pattern("100%%-#.exr", 3, true), "100%-3.exr");
  EXPECT_EQ(expand_frame_pattern("a%s%4d%011d%0d.exr", 3, true), "a%s%4d%011d%0d.exr");
  EXPECT_EQ(expand_frame_pattern("shot.%04d.exr", 12345, true), "shot.12345.exr");
  EXPECT_EQ(expand_frame_pattern("shot.%04d.exr", -7, true), "shot.-007.exr");
  EXPECT_EQ(expand_frame_pattern("shot.%d.exr", -7, true), "shot.-7.exr");
  EXPECT_TRUE(is_frame_pattern("shot.%04d.exr", true));
  EXPECT_FALSE(is_frame_pattern("shot.%04d.exr"));
  EXPECT_TRUE(is_frame_pattern("shot.#.exr"));
  EXPECT_FALSE(is_frame_pattern("shot.exr", true));
  EXPECT_FALSE(is_frame_pattern("100%%.exr", true));
}

}  // namespace
}  // namespace rf
