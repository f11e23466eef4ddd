// The invariant layer (engine/check.h): RF_CHECK holds in every build and names the file, line
// and condition; RF_DCHECK holds where kDchecks is set (debug and sanitizer builds) and does not
// evaluate its operands elsewhere; the checks at the engine's borders fire on a broken caller.
#include <gtest/gtest.h>

#include <string>

#include "engine/check.h"
#include "engine/distribution.h"
#include "engine/render.h"
#include "tests/support/fixtures.h"

namespace rf {
namespace {

TEST(Check, AFailedCheckNamesTheFileLineAndCondition) {
  int evaluated = 0;
  auto message = [&] {
    ++evaluated;
    return std::string("the sum");
  };
  RF_CHECK(1 + 1 == 2, message());
  EXPECT_EQ(evaluated, 0) << "the message is built only when the check fails";
  const int line = __LINE__ + 2;
  try {
    RF_CHECK(1 + 1 == 3, message());
    FAIL() << "RF_CHECK did not throw";
  } catch (const CheckFailure& e) {
    EXPECT_EQ(std::string(e.what()),
              "internal error: tests/check_test.cpp:" + std::to_string(line) +
                  ": check failed: 1 + 1 == 3 (the sum)");
  }
  EXPECT_EQ(evaluated, 1);
}

TEST(Check, ADcheckHoldsOnlyWhereDchecksAreOn) {
  int evaluated = 0;
  auto broken = [&] {
    ++evaluated;
    return false;
  };
  if (kDchecks) {
    EXPECT_THROW(RF_DCHECK(broken(), ""), CheckFailure);
    EXPECT_EQ(evaluated, 1);
  } else {
    RF_DCHECK(broken(), "");
    EXPECT_EQ(evaluated, 0) << "a release build evaluates no RF_DCHECK operand";
  }
}

TEST(Check, TheEngineBordersCatchABrokenCaller) {
  EXPECT_THROW(Distribution1D(std::vector<float>{}), CheckFailure);
  Scene scene = test::cornell_box({"path", 16, 1, 1, 2});
  Renderer renderer(scene);
  EXPECT_THROW(renderer.render(TaskKey{0, Rect{8, 8, 16, 16}, 0}, false), CheckFailure)
      << "a task rect outside the film";
  EXPECT_THROW(renderer.render(TaskKey{0, Rect{0, 0, 0, 4}, 0}, false), CheckFailure)
      << "an empty task rect";
  EXPECT_NO_THROW(renderer.render(TaskKey{0, Rect{0, 0, 16, 16}, 0}, false));
}

}  // namespace
}  // namespace rf
