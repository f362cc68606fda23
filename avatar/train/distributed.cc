#include "avatar/train/distributed.h"

#include <torch/torch.h>

#include <arpa/inet.h>
#include <netdb.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <map>

#include "avatar/model_table.h"

#ifdef HEADFORGE_WITH_GLOO
#include <torch/csrc/distributed/c10d/ProcessGroupGloo.hpp>
#include <torch/csrc/distributed/c10d/TCPStore.hpp>
#endif

namespace headforge {

std::string LocalAddressToward(const std::string& host, int port) {
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_DGRAM;
  addrinfo* found = nullptr;
  if (::getaddrinfo(host.c_str(), std::to_string(port).c_str(), &hints, &found) != 0) return "";
  std::string out;
  for (const addrinfo* a = found; a != nullptr && out.empty(); a = a->ai_next) {
    // A datagram socket's connect sends nothing: it only picks the route,
    // and with it the local address.
    const int fd = ::socket(a->ai_family, SOCK_DGRAM, 0);
    if (fd < 0) continue;
    sockaddr_storage local{};
    socklen_t length = sizeof(local);
    if (::connect(fd, a->ai_addr, a->ai_addrlen) == 0 &&
        ::getsockname(fd, reinterpret_cast<sockaddr*>(&local), &length) == 0) {
      char text[INET6_ADDRSTRLEN] = {};
      const void* where = local.ss_family == AF_INET
                              ? static_cast<const void*>(&reinterpret_cast<const sockaddr_in*>(&local)->sin_addr)
                              : static_cast<const void*>(&reinterpret_cast<const sockaddr_in6*>(&local)->sin6_addr);
      if (::inet_ntop(local.ss_family, where, text, sizeof(text)) != nullptr) out = text;
    }
    ::close(fd);
  }
  ::freeaddrinfo(found);
  return out;
}

namespace {

std::string Env(const char* name) {
  const char* value = std::getenv(name);
  return value ? value : "";
}

// `text` as a whole number in [low, high], or an error naming `name`.
Status ParseInt(const std::string& name, const std::string& text, int low, int high, int* out) {
  char* end = nullptr;
  const long value = std::strtol(text.c_str(), &end, 10);
  if (text.empty() || *end != '\0' || value < low || value > high)
    return Status::InvalidArgument("distributed training: " + name + "='" + text + "' is not a whole number in [" +
                                   std::to_string(low) + ", " + std::to_string(high) + "]");
  *out = int(value);
  return Status::Ok();
}

}  // namespace

Status CheckDataParallelModel(const std::string& model, const std::string& program) {
  if (kGaussianStyle.Is(model)) return Status::Ok();
  return Status::InvalidArgument("data-parallel training: the " + model +
                                 " model trains in one process (it has no ranks' share of views yet); run " + program +
                                 " once, or --distributed off");
}

std::string FirstSlurmHost(const std::string& nodes) {
  // The first entry: up to a comma outside brackets.
  int depth = 0;
  size_t end = 0;
  for (; end < nodes.size(); ++end) {
    if (nodes[end] == '[') ++depth;
    if (nodes[end] == ']') --depth;
    if (nodes[end] == ',' && depth == 0) break;
  }
  const std::string first = nodes.substr(0, end);
  const size_t open = first.find('[');
  if (open == std::string::npos) return first;
  // prefix[07-09,12]suffix: the range's first number, its zeros kept.
  const size_t stop = first.find_first_of("-,]", open + 1);
  const size_t close = first.find(']', open);
  return first.substr(0, open) + first.substr(open + 1, stop - open - 1) +
         (close == std::string::npos ? "" : first.substr(close + 1));
}

Status ReadDistributedSetup(const std::string& mode, DistributedSetup* setup) {
  *setup = DistributedSetup();
  if (mode == "off") return Status::Ok();
  if (mode != "auto") return Status::InvalidArgument("--distributed must be auto or off, not '" + mode + "'");
  const std::string port = Env("MASTER_PORT");
  if (!Env("WORLD_SIZE").empty() || !Env("RANK").empty()) {
    if (Env("WORLD_SIZE").empty() || Env("RANK").empty())
      return Status::InvalidArgument("distributed training: RANK and WORLD_SIZE go together (torchrun sets both); "
                                     "unset both for one process");
    HF_RETURN_IF_ERROR(ParseInt("WORLD_SIZE", Env("WORLD_SIZE"), 1, 65536, &setup->world));
    HF_RETURN_IF_ERROR(ParseInt("RANK", Env("RANK"), 0, setup->world - 1, &setup->rank));
    if (!Env("MASTER_ADDR").empty()) setup->address = Env("MASTER_ADDR");
    if (!port.empty()) HF_RETURN_IF_ERROR(ParseInt("MASTER_PORT", port, 1, 65535, &setup->port));
    setup->source = "torchrun";
    return Status::Ok();
  }
  // srun's step (a batch script's own shell has SLURM_NTASKS but is one process).
  const std::string tasks = Env("SLURM_STEP_NUM_TASKS");
  if (!tasks.empty() && tasks != "1") {
    HF_RETURN_IF_ERROR(ParseInt("SLURM_STEP_NUM_TASKS", tasks, 1, 65536, &setup->world));
    HF_RETURN_IF_ERROR(ParseInt("SLURM_PROCID", Env("SLURM_PROCID"), 0, setup->world - 1, &setup->rank));
    const std::string nodes = !Env("SLURM_STEP_NODELIST").empty() ? Env("SLURM_STEP_NODELIST") : Env("SLURM_JOB_NODELIST");
    if (!Env("MASTER_ADDR").empty()) {
      setup->address = Env("MASTER_ADDR");
    } else if (!nodes.empty()) {
      setup->address = FirstSlurmHost(nodes);
    }
    if (!port.empty()) {
      HF_RETURN_IF_ERROR(ParseInt("MASTER_PORT", port, 1, 65535, &setup->port));
    } else {
      // One port per job, so that two jobs on one node do not meet.
      int job = 0;
      if (ParseInt("SLURM_JOB_ID", Env("SLURM_JOB_ID"), 0, 2000000000, &job).ok()) setup->port = 29500 + job % 1000;
    }
    setup->source = "slurm";
  }
  return Status::Ok();
}

#ifdef HEADFORGE_WITH_GLOO

struct ProcessGroup::Impl {
  c10::intrusive_ptr<c10d::Store> store;
  c10::intrusive_ptr<c10d::ProcessGroupGloo> group;
};

ProcessGroup::~ProcessGroup() = default;

Status ProcessGroup::Connect(const DistributedSetup& setup, double timeout_s, std::unique_ptr<ProcessGroup>* out) {
  const auto timeout = std::chrono::milliseconds(int64_t(1000 * timeout_s));
  std::unique_ptr<ProcessGroup> group(new ProcessGroup());
  group->rank_ = setup.rank;
  group->world_ = setup.world;
  group->impl_ = std::make_unique<Impl>();
  try {
    c10d::TCPStoreOptions options;
    options.port = uint16_t(setup.port);
    options.isServer = setup.rank == 0;
    options.numWorkers = size_t(setup.world);
    options.waitWorkers = true;
    options.timeout = timeout;
    group->impl_->store = c10::make_intrusive<c10d::TCPStore>(setup.address, options);
    auto gloo = c10d::ProcessGroupGloo::Options::create(timeout);
    // GLOO_SOCKET_IFNAME's interface where it is set; else this host's
    // address on the route to rank 0, which the other ranks reach it at
    // (this host's name may say 127.0.1.1, as Debian's /etc/hosts has it);
    // else gloo's choice from the host's name.
    const char* interface = std::getenv("GLOO_SOCKET_IFNAME");
    if (interface != nullptr && *interface != '\0') {
      gloo->devices.push_back(c10d::ProcessGroupGloo::createDeviceForInterface(interface));
    } else {
      const std::string local = LocalAddressToward(setup.address, setup.port);
      if (!local.empty()) {
        gloo->devices.push_back(c10d::ProcessGroupGloo::createDeviceForHostname(local));
      } else {
        gloo->devices.push_back(c10d::ProcessGroupGloo::createDefaultDevice());
      }
    }
    group->impl_->group = c10::make_intrusive<c10d::ProcessGroupGloo>(group->impl_->store, setup.rank, setup.world, gloo);
  } catch (const std::exception& e) {
    std::string what = e.what();
    what = what.substr(0, what.find('\n'));
    return Status::IoError("distributed training: rank " + std::to_string(setup.rank) + " of " +
                               std::to_string(setup.world) + " could not meet the others at " + setup.address + ":" +
                               std::to_string(setup.port) + " within " + std::to_string(int(timeout_s)) +
                               " s (" + what + "); start every rank with the same MASTER_ADDR and MASTER_PORT, "
                               "a port free on rank 0's host");
  }
  *out = std::move(group);
  return Status::Ok();
}

Status ProcessGroup::AnyOf(std::vector<uint8_t>* flags) {
  try {
    torch::Tensor t = torch::tensor(std::vector<int32_t>(flags->begin(), flags->end()), torch::kInt32);
    std::vector<at::Tensor> tensors = {t};
    c10d::AllreduceOptions max;
    max.reduceOp = c10d::ReduceOp::MAX;
    impl_->group->allreduce(tensors, max)->wait();
    for (size_t i = 0; i < flags->size(); ++i) (*flags)[i] = t[int64_t(i)].item<int32_t>() != 0;
  } catch (const std::exception& e) {
    std::string what = e.what();
    return Status::IoError("distributed training: another rank has gone (" + what.substr(0, what.find('\n')) + ")");
  }
  return Status::Ok();
}

void ProcessGroup::AllReduceSum(const std::vector<torch::Tensor>& tensors) {
  torch::NoGradGuard no_grad;
  // One flat buffer per dtype and device, in the order given.
  std::map<std::pair<int, std::string>, std::vector<torch::Tensor>> buckets;
  for (const torch::Tensor& t : tensors)
    buckets[{int(t.scalar_type()), t.device().str()}].push_back(t);
  try {
    for (auto& [key, members] : buckets) {
      std::vector<torch::Tensor> flat;
      for (const torch::Tensor& t : members) flat.push_back(t.reshape({-1}));
      std::vector<at::Tensor> buffer = {torch::cat(flat)};
      impl_->group->allreduce(buffer)->wait();
      int64_t at = 0;
      for (const torch::Tensor& t : members) {
        t.copy_(buffer[0].slice(0, at, at + t.numel()).view(t.sizes()));
        at += t.numel();
      }
    }
  } catch (const DistributedFailure&) {
    throw;
  } catch (const std::exception& e) {
    std::string what = e.what();
    throw DistributedFailure("distributed training: another rank has gone (" + what.substr(0, what.find('\n')) + ")");
  }
}

#else

struct ProcessGroup::Impl {};
ProcessGroup::~ProcessGroup() = default;

Status ProcessGroup::Connect(const DistributedSetup& setup, double, std::unique_ptr<ProcessGroup>*) {
  return Status::IoError("distributed training: this build has no c10d backend (it was built without gloo's "
                             "headers: apt-get install libgloo-dev, then build again); " +
                             std::to_string(setup.world) + " ranks were asked for by " + setup.source +
                             "'s variables (--distributed off trains in one process)");
}
Status ProcessGroup::AnyOf(std::vector<uint8_t>*) { return Status::IoError("no process group"); }
void ProcessGroup::AllReduceSum(const std::vector<torch::Tensor>&) { throw DistributedFailure("no process group"); }

#endif

}  // namespace headforge
