// Tests of engine/pass_set: sets of pass indices, their text form and its errors.
#include "engine/pass_set.h"

#include <gtest/gtest.h>

#include "tests/support/fixtures.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

TEST(PassSet, CountOverlapsAndPrefix) {
  PassSet a = PassSet::range(0, 4);
  EXPECT_EQ(a.count(), 4u);
  EXPECT_TRUE(a.is_prefix());
  EXPECT_TRUE(PassSet{}.is_prefix());
  EXPECT_TRUE(PassSet::range(3, 3).empty());
  EXPECT_FALSE(PassSet::range(1, 4).is_prefix());
  EXPECT_TRUE(a.overlaps(PassSet::range(3, 5)));
  EXPECT_FALSE(a.overlaps(PassSet::range(4, 5)));  // half-open: touching is not overlapping
  EXPECT_FALSE(a.overlaps(PassSet{}));
}

TEST(PassSet, AddKeepsSortedAndCoalesces) {
  PassSet s = PassSet::range(8, 12);
  s.add(PassSet::range(0, 2));
  EXPECT_EQ(s.ranges.size(), 2u);
  EXPECT_EQ(s.ranges[0], std::make_pair(0u, 2u));
  s.add(PassSet::range(2, 8));  // fills the gap: one range
  ASSERT_EQ(s.ranges.size(), 1u);
  EXPECT_EQ(s.ranges[0], std::make_pair(0u, 12u));
  EXPECT_EQ(s.count(), 12u);
  EXPECT_TRUE(s.is_prefix());
  // Adding passes one by one in any order gives the same set as the range.
  PassSet t;
  for (uint32_t p : {5u, 1u, 3u, 0u, 4u, 2u}) t.add(PassSet::range(p, p + 1));
  EXPECT_EQ(t, PassSet::range(0, 6));
}

TEST(PassSet, ToStringAndParseRoundTrip) {
  PassSet s = PassSet::range(0, 4);
  s.add(PassSet::range(8, 12));
  s.add(PassSet::range(20, 21));
  EXPECT_EQ(s.to_string(), "0-3,8-11,20");
  EXPECT_EQ(PassSet::range(5, 6).to_string(), "5");
  EXPECT_EQ(PassSet{}.to_string(), "");
  for (const char* text : {"", "0", "5", "0-3,8-11", "0-3,8-11,20", "4294967293"}) {
    EXPECT_EQ(PassSet::parse(text).to_string(), text);
  }
  EXPECT_EQ(PassSet::parse("8-11,0-3"), PassSet::parse("0-3,8-11"));  // order does not matter
  EXPECT_EQ(PassSet::parse("0-1,2-3"), PassSet::range(0, 4));         // adjacent ranges coalesce
}

TEST(PassSet, ParseRejectsWithClearMessages) {
  for (const char* bad : {"a", "1-", "-1", "3-1", "1,,2", "1,", " 1", "1-2-3", "0-3,2",
                          "4294967295", "99999999999"}) {
    EXPECT_THROW(PassSet::parse(bad), std::invalid_argument) << bad;
  }
  EXPECT_NE(test::error_of([] { PassSet::parse("3-1"); }).find("ends before it begins"),
            std::string::npos);
  EXPECT_NE(test::error_of([] { PassSet::parse("0-3,2-5"); }).find("2-3 listed twice"),
            std::string::npos);
  EXPECT_NE(test::error_of([] { PassSet::parse("x"); }).find("\"x\""), std::string::npos);
}

}  // namespace
}  // namespace rf
