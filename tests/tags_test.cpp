// Worker tags and job requirements (farm/tags.h): their syntax, matching (presence, value,
// numeric at-least), a job's pool, and the tags every worker advertises.
#include "farm/tags.h"

#include <gtest/gtest.h>

#include "engine/build_info.h"

namespace rf {
namespace {

TEST(Tags, SyntaxOfTagsAndRequirements) {
  for (const char* ok : {"gpu", "pool=lighting", "isa=x86_64-avx512", "memory_gb=64", "a.b-c_d=1"})
    EXPECT_EQ(tag_problem(ok), "") << ok;
  for (const char* bad :
       {"", "=x", "Gpu", "9lives", "pool=", "pool=a b", "pool=a,b", "memory_gb>=64", "pool=a\nb"})
    EXPECT_NE(tag_problem(bad), "") << bad;
  EXPECT_NE(tag_problem(std::string(65, 'a')), "");
  EXPECT_NE(tag_problem("pool=" + std::string(129, 'x')), "");
  // Requirements add '>=' with a number.
  for (const char* ok : {"gpu", "pool=lighting", "memory_gb>=64", "cores>=0.5"})
    EXPECT_EQ(requirement_problem(ok), "") << ok;
  for (const char* bad : {"memory_gb>=lots", "memory_gb>=", ">=4", "GPU"})
    EXPECT_NE(requirement_problem(bad), "") << bad;
  // Messages quote the text printably.
  EXPECT_NE(tag_problem("pool=a\x1b[2Jb").find("\\x1b"), std::string::npos)
      << tag_problem("pool=a\x1b[2Jb");
}

TEST(Tags, RequirementsMatchPresenceValuesAndNumbers) {
  const std::vector<std::string> tags{"gpu", "pool=lighting", "memory_gb=64", "cores=16"};
  EXPECT_TRUE(satisfies(tags, "gpu"));
  EXPECT_TRUE(satisfies(tags, "pool"));
  EXPECT_TRUE(satisfies(tags, "pool=lighting"));
  EXPECT_FALSE(satisfies(tags, "pool=fx"));
  EXPECT_FALSE(satisfies(tags, "gpu=1")) << "a bare tag has no value";
  EXPECT_TRUE(satisfies(tags, "memory_gb>=64"));
  EXPECT_TRUE(satisfies(tags, "memory_gb>=32.5"));
  EXPECT_FALSE(satisfies(tags, "memory_gb>=65"));
  EXPECT_FALSE(satisfies(tags, "gpu>=1")) << "no value to compare";
  EXPECT_FALSE(satisfies(tags, "fast"));
  EXPECT_TRUE(satisfies_all(tags, {}));
  EXPECT_TRUE(satisfies_all(tags, {"gpu", "cores>=8"}));
  EXPECT_FALSE(satisfies_all(tags, {"gpu", "cores>=32"}));
  EXPECT_EQ(pool_of({"gpu", "pool=lighting"}), "lighting");
  EXPECT_EQ(pool_of({"gpu", "pool"}), "") << "a pool is named";
  EXPECT_EQ(pool_of({}), "");
}

TEST(Tags, EveryWorkerAdvertisesItsKindCoresAndMemory) {
  std::vector<std::string> tags = automatic_tags();
  ASSERT_GE(tags.size(), 2u);
  for (const std::string& t : tags) EXPECT_EQ(tag_problem(t), "") << t;
  const std::string kind = cpu_isa();
  EXPECT_EQ(tags[0], "isa=" + kind.substr(0, kind.find(' ')));
  EXPECT_TRUE(satisfies(tags, "cores>=1"));
  EXPECT_TRUE(satisfies(tags, "memory_gb>=0"));
}

}  // namespace
}  // namespace rf
