// CollapseWatch: a run of perfect discriminator steps of the given length
// fires once; any imperfect step starts the count again; 0 never fires.
#include <gtest/gtest.h>

#include "avatar/train/gan_watch.h"

namespace headforge {
namespace {

TEST(CollapseWatch, FiresOnceWhenTheDiscriminatorIsPerfectForTheGivenSteps) {
  CollapseWatch watch(3);
  EXPECT_FALSE(watch.Observe(1.0, 1.0));
  EXPECT_FALSE(watch.Observe(1.0, 1.0));
  EXPECT_FALSE(watch.Observe(1.0, 0.99));  // one generated image fooled it: the run starts again
  EXPECT_EQ(watch.run(), 0);
  EXPECT_FALSE(watch.Observe(1.0, 1.0));
  EXPECT_FALSE(watch.Observe(1.0, 1.0));
  EXPECT_TRUE(watch.Observe(1.0, 1.0));
  EXPECT_FALSE(watch.Observe(1.0, 1.0));  // once per run
  EXPECT_EQ(watch.run(), 4);
  EXPECT_FALSE(watch.Observe(0.5, 1.0));
  EXPECT_NE(watch.Warning("stage 3's prior").find("3 steps in a row"), std::string::npos);
  // Restored from a checkpoint mid-run, it goes on counting.
  CollapseWatch resumed(3);
  resumed.set_run(2);
  EXPECT_TRUE(resumed.Observe(1.0, 1.0));
  CollapseWatch never(0);
  for (int i = 0; i < 10; ++i) EXPECT_FALSE(never.Observe(1.0, 1.0));
}

}  // namespace
}  // namespace headforge
