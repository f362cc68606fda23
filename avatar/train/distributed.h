// Several processes training one model (data-parallel): each process (a
// rank) takes its share of every step's views, and their gradients are
// summed over all ranks before the optimiser's step, so that every rank
// holds the same model after it. The ranks find one another as torchrun and
// Slurm tell them (RANK, WORLD_SIZE, MASTER_ADDR, MASTER_PORT; or
// SLURM_PROCID, srun's SLURM_STEP_NUM_TASKS and the first host of the step's node list) and
// talk through LibTorch's c10d: a TCPStore for the rendezvous and
// ProcessGroupGloo for the sums (on CPU tensors, and CUDA ones by copy).
#pragma once

#include <torch/types.h>

#include <memory>
#include <string>
#include <vector>

#include "avatar/train/loop.h"
#include "core/status.h"

namespace headforge {

struct DistributedSetup {
  int rank = 0, world = 1;
  std::string address = "127.0.0.1";  // rank 0's host, where the store listens
  int port = 29500;
  std::string source;  // where the figures came from: "torchrun", "slurm" or "" (one process)
};

// The setup `mode` asks for: "off" (one process, whatever the environment
// says), or "auto": torchrun's variables where RANK and WORLD_SIZE are set,
// else Slurm's where srun's SLURM_STEP_NUM_TASKS is above 1 (SLURM_PROCID the rank, the
// first host of SLURM_STEP_NODELIST or SLURM_JOB_NODELIST the address,
// MASTER_PORT or 29500 plus the job's id modulo 1000 the port), else one
// process. A value that does not parse is an error naming the variable.
Status ReadDistributedSetup(const std::string& mode, DistributedSetup* setup);

// Only the gaussian-style model trains over ranks: `model` other than it
// is refused, naming `program` (headforge train, headforge-train) to run
// once instead.
Status CheckDataParallelModel(const std::string& model, const std::string& program);

// This host's address on the route to `host` (rank 0's, a name or an
// address; `port` its store's): where the other ranks can reach this one.
// Empty when `host` does not resolve or no route leads to it.
std::string LocalAddressToward(const std::string& host, int port);

// "node[07-09,12],gpu3" -> "node07": the first host of a Slurm node list.
std::string FirstSlurmHost(const std::string& nodes);

// The ranks of one run, connected. AllReduceSum throws DistributedFailure
// (loop.h) when a peer has gone or none has answered within the timeout:
// the loop ends the run with its message.
class ProcessGroup final : public Collective {
 public:
  ~ProcessGroup() override;
  // Connects to the other ranks of `setup` (rank 0 listens on its port):
  // fails when they have not all come within `timeout_s` or this build has
  // no c10d backend.
  static Status Connect(const DistributedSetup& setup, double timeout_s, std::unique_ptr<ProcessGroup>* group);

  int rank() const override { return rank_; }
  int world() const override { return world_; }
  Status AnyOf(std::vector<uint8_t>* flags) override;
  // Sums each tensor over the ranks, in place: the tensors of one dtype and
  // device travel as one flat buffer.
  void AllReduceSum(const std::vector<torch::Tensor>& tensors);

 private:
  struct Impl;
  ProcessGroup() = default;
  std::unique_ptr<Impl> impl_;
  int rank_ = 0, world_ = 1;
};

}  // namespace headforge
