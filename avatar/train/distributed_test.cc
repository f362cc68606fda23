// The ranks of a data-parallel training: their figures from torchrun's and
// Slurm's variables, and two ranks of one process group (two threads of
// this process, each its own rank) summing tensors and agreeing on flags.
#include "avatar/train/distributed.h"

#include <gtest/gtest.h>
#include <torch/torch.h>

#include <cstdlib>
#include <optional>
#include <thread>

#include "tests/free_port.h"

namespace headforge {
namespace {

// Sets the variables given (nullptr: unset) for the scope's life, and unsets
// every other the setup reads.
class Environment {
 public:
  explicit Environment(const std::vector<std::pair<const char*, const char*>>& values) {
    for (const char* name : {"RANK", "WORLD_SIZE", "MASTER_ADDR", "MASTER_PORT", "SLURM_PROCID", "SLURM_NTASKS", "SLURM_STEP_NUM_TASKS",
                             "SLURM_STEP_NODELIST", "SLURM_JOB_NODELIST", "SLURM_JOB_ID"}) {
      const char* old = std::getenv(name);
      saved_.push_back({name, old ? std::optional<std::string>(old) : std::nullopt});
      ::unsetenv(name);
    }
    for (const auto& [name, value] : values)
      if (value) ::setenv(name, value, 1);
  }
  ~Environment() {
    for (const auto& [name, value] : saved_) {
      if (value) {
        ::setenv(name.c_str(), value->c_str(), 1);
      } else {
        ::unsetenv(name.c_str());
      }
    }
  }

 private:
  std::vector<std::pair<std::string, std::optional<std::string>>> saved_;
};

TEST(DistributedSetup, SlurmNodeListsGiveTheirFirstHost) {
  EXPECT_EQ(FirstSlurmHost("vm"), "vm");
  EXPECT_EQ(FirstSlurmHost("gpu3,gpu4"), "gpu3");
  EXPECT_EQ(FirstSlurmHost("node[07-09,12],gpu3"), "node07");
  EXPECT_EQ(FirstSlurmHost("node[12,07-09]"), "node12");
  EXPECT_EQ(FirstSlurmHost("rack[2-3]-n[01-04]"), "rack2-n[01-04]");
}

// Where the other ranks reach this one: the local end of the route to rank
// 0's host (this machine's loopback for itself), nothing for a host that
// does not resolve.
TEST(DistributedSetup, ThisHostsAddressIsTheOneOnTheRouteToRankZero) {
  EXPECT_EQ(LocalAddressToward("127.0.0.1", 29500), "127.0.0.1");
  EXPECT_EQ(LocalAddressToward("localhost", 29500).rfind("127.", 0) == 0 ||
                LocalAddressToward("localhost", 29500) == "::1",
            true)
      << LocalAddressToward("localhost", 29500);
  EXPECT_EQ(LocalAddressToward("no-such-host.invalid", 29500), "");
}

TEST(DistributedSetup, TorchrunsAndSlurmsVariablesNameTheRanks) {
  DistributedSetup s;
  {
    Environment env({});
    ASSERT_TRUE(ReadDistributedSetup("auto", &s).ok());
    EXPECT_EQ(s.world, 1);
    EXPECT_EQ(s.source, "");
  }
  {
    Environment env({{"RANK", "3"}, {"WORLD_SIZE", "4"}, {"MASTER_ADDR", "node07"}, {"MASTER_PORT", "29400"}});
    ASSERT_TRUE(ReadDistributedSetup("auto", &s).ok());
    EXPECT_EQ(s.rank, 3);
    EXPECT_EQ(s.world, 4);
    EXPECT_EQ(s.address, "node07");
    EXPECT_EQ(s.port, 29400);
    EXPECT_EQ(s.source, "torchrun");
    // off: one process whatever the variables say.
    ASSERT_TRUE(ReadDistributedSetup("off", &s).ok());
    EXPECT_EQ(s.world, 1);
  }
  {
    Environment env({{"SLURM_PROCID", "1"}, {"SLURM_NTASKS", "2"}, {"SLURM_STEP_NUM_TASKS", "2"},
                     {"SLURM_JOB_NODELIST", "gpu[05-06]"}, {"SLURM_JOB_ID", "123456"}});
    ASSERT_TRUE(ReadDistributedSetup("auto", &s).ok());
    EXPECT_EQ(s.rank, 1);
    EXPECT_EQ(s.world, 2);
    EXPECT_EQ(s.address, "gpu05");
    EXPECT_EQ(s.port, 29500 + 456);  // one port per job
    EXPECT_EQ(s.source, "slurm");
  }
  {
    // One task of a Slurm job, or a batch script of several tasks run
    // without srun (its own shell is one process): one process.
    Environment env({{"SLURM_PROCID", "0"}, {"SLURM_NTASKS", "4"}});
    ASSERT_TRUE(ReadDistributedSetup("auto", &s).ok());
    EXPECT_EQ(s.world, 1);
  }
  // What does not parse is named.
  for (const auto& [values, named] :
       std::vector<std::pair<std::vector<std::pair<const char*, const char*>>, std::string>>{
           {{{"RANK", "2"}, {"WORLD_SIZE", "2"}}, "RANK='2'"},
           {{{"RANK", "0"}, {"WORLD_SIZE", "two"}}, "WORLD_SIZE='two'"},
           {{{"RANK", "0"}}, "RANK and WORLD_SIZE go together"},
           {{{"RANK", "0"}, {"WORLD_SIZE", "2"}, {"MASTER_PORT", "99999"}}, "MASTER_PORT='99999'"},
           {{{"SLURM_STEP_NUM_TASKS", "2"}}, "SLURM_PROCID=''"}}) {
    Environment env(values);
    const Status status = ReadDistributedSetup("auto", &s);
    EXPECT_FALSE(status.ok()) << named;
    EXPECT_NE(status.message().find(named), std::string::npos) << status.message();
  }
  EXPECT_NE(ReadDistributedSetup("on", &s).message().find("auto or off"), std::string::npos);
}

#ifdef HEADFORGE_WITH_GLOO
// Two ranks (threads of this process): tensors of two dtypes, one of them
// not contiguous, summed in place; a flag one rank raises reaches both.
TEST(ProcessGroupTest, TwoRanksSumTensorsAndShareAStop) {
  const int port = FreePort();
  ASSERT_GT(port, 0);
  std::vector<torch::Tensor> results[2];
  std::vector<uint8_t> flags[2];
  Status status[2];
  auto rank = [&](int r) {
    DistributedSetup setup;
    setup.rank = r;
    setup.world = 2;
    setup.port = port;
    std::unique_ptr<ProcessGroup> group;
    status[r] = ProcessGroup::Connect(setup, 30, &group);
    if (!status[r].ok()) return;
    const torch::Tensor a = torch::arange(6, torch::kFloat32).view({2, 3}) * (r + 1);
    const torch::Tensor b = torch::full({4}, 0.25 * (r + 1), torch::kFloat64);
    const torch::Tensor c = torch::arange(6, torch::kFloat32).view({3, 2}).t() * (r + 1);  // not contiguous
    group->AllReduceSum({a, b, c});
    results[r] = {a, b, c};
    flags[r] = {uint8_t(r == 1), 0};
    status[r] = group->AnyOf(&flags[r]);
  };
  std::thread one(rank, 1);
  rank(0);
  one.join();
  for (int r = 0; r < 2; ++r) {
    ASSERT_TRUE(status[r].ok()) << status[r].message();
    EXPECT_TRUE(torch::equal(results[r][0], torch::arange(6, torch::kFloat32).view({2, 3}) * 3)) << r;
    EXPECT_TRUE(torch::equal(results[r][1], torch::full({4}, 0.75, torch::kFloat64))) << r;
    EXPECT_TRUE(torch::equal(results[r][2], torch::arange(6, torch::kFloat32).view({3, 2}).t() * 3)) << r;
    EXPECT_EQ(flags[r], (std::vector<uint8_t>{1, 0})) << r;
  }
}

// A rank whose peer never comes fails after the timeout, saying where it waited.
TEST(ProcessGroupTest, ARankAloneFailsAfterTheTimeout) {
  DistributedSetup setup;
  setup.rank = 0;
  setup.world = 2;
  setup.port = FreePort();
  std::unique_ptr<ProcessGroup> group;
  const auto start = std::chrono::steady_clock::now();
  const Status status = ProcessGroup::Connect(setup, 1, &group);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  EXPECT_FALSE(status.ok());
  EXPECT_NE(status.message().find("could not meet the others at 127.0.0.1:" + std::to_string(setup.port)),
            std::string::npos)
      << status.message();
  EXPECT_LT(seconds, 15);
}
#endif

}  // namespace
}  // namespace headforge
