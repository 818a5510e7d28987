#include "unsup_mvs/core/distributed.h"

#include <torch/torch.h>

#include <chrono>
#include <cstdlib>
#include <stdexcept>

#ifdef UMVS_HAVE_GLOO
#include <torch/csrc/distributed/c10d/ProcessGroupGloo.hpp>
#include <torch/csrc/distributed/c10d/TCPStore.hpp>
#endif

namespace umvs {

void DistributedConfig::validate() const {
  if (world_size < 1) throw std::invalid_argument("world size must be >= 1, got " + std::to_string(world_size));
  if (rank < 0 || rank >= world_size) {
    throw std::invalid_argument("rank must be in 0.." + std::to_string(world_size - 1) + ", got " + std::to_string(rank));
  }
  if (master_port < 1 || master_port > 65535) {
    throw std::invalid_argument("master port must be in 1..65535, got " + std::to_string(master_port));
  }
  if (master_addr.empty()) throw std::invalid_argument("master address is empty");
  if (!(timeout_seconds > 0)) throw std::invalid_argument("the distributed timeout must be > 0 seconds");
}

DistributedConfig distributed_config_from_environment(DistributedConfig base) {
  auto integer = [](const char* name, int* value) {
    const char* text = std::getenv(name);
    if (!text || !*text) return;
    try {
      size_t used = 0;
      const int v = std::stoi(text, &used);
      if (used != std::string(text).size()) throw std::invalid_argument("trailing characters");
      *value = v;
    } catch (const std::exception&) {
      throw std::invalid_argument(std::string(name) + "='" + text + "' is not a whole number");
    }
  };
  integer("WORLD_SIZE", &base.world_size);
  integer("RANK", &base.rank);
  integer("MASTER_PORT", &base.master_port);
  if (const char* addr = std::getenv("MASTER_ADDR"); addr && *addr) base.master_addr = addr;
  return base;
}

#ifdef UMVS_HAVE_GLOO

bool distributed_available() { return true; }

struct ProcessGroup::Impl {
  c10::intrusive_ptr<c10d::TCPStore> store;
  c10::intrusive_ptr<c10d::ProcessGroupGloo> group;
  int shared = 0;  // share_from_rank0 calls so far (the store key of the next one)
};

namespace {
// Collectives report a dead peer as a gloo or c10 exception: name the rank in the message.
template <class F>
void collective(const DistributedConfig& config, const char* what, F&& f) {
  try {
    f();
  } catch (const std::exception& e) {
    throw std::runtime_error("rank " + std::to_string(config.rank) + " of " + std::to_string(config.world_size) + ": " +
                             what + " failed (another rank died or is unreachable?): " + e.what());
  }
}
}  // namespace

ProcessGroup::ProcessGroup(const DistributedConfig& config) : config_(config), impl_(std::make_unique<Impl>()) {
  config_.validate();
  const auto timeout = std::chrono::milliseconds(static_cast<int64_t>(config_.timeout_seconds * 1000));
  try {
    c10d::TCPStoreOptions options;
    options.port = static_cast<std::uint16_t>(config_.master_port);
    options.isServer = config_.rank == 0;
    options.numWorkers = static_cast<size_t>(config_.world_size);
    options.waitWorkers = true;
    options.timeout = timeout;
    impl_->store = c10::make_intrusive<c10d::TCPStore>(config_.master_addr, options);
    auto gloo = c10d::ProcessGroupGloo::Options::create(timeout);
    const bool loopback = config_.master_addr == "127.0.0.1" || config_.master_addr == "localhost";
    // On one machine the ranks talk over loopback; across hosts over the interface of this host's name.
    gloo->devices.push_back(loopback ? c10d::ProcessGroupGloo::createDeviceForHostname("127.0.0.1")
                                     : c10d::ProcessGroupGloo::createDefaultDevice());
    impl_->group = c10::make_intrusive<c10d::ProcessGroupGloo>(impl_->store, config_.rank, config_.world_size, gloo);
  } catch (const std::exception& e) {
    throw std::runtime_error("rank " + std::to_string(config_.rank) + " of " + std::to_string(config_.world_size) +
                             ": cannot join the job at " + config_.master_addr + ":" +
                             std::to_string(config_.master_port) + " within " +
                             std::to_string(config_.timeout_seconds) + " s: " + e.what());
  }
}

ProcessGroup::~ProcessGroup() = default;

void ProcessGroup::broadcast_from_rank0(const std::vector<torch::Tensor>& tensors) {
  collective(config_, "broadcast", [&] {
    for (const auto& t : tensors) {
      std::vector<at::Tensor> one = {t.detach().to(torch::kCPU).contiguous()};
      impl_->group->broadcast(one, c10d::BroadcastOptions{0})->wait();
      torch::NoGradGuard no_grad;
      t.copy_(one[0]);
    }
  });
}

void ProcessGroup::average(const std::vector<torch::Tensor>& tensors) {
  if (tensors.empty()) return;
  std::vector<torch::Tensor> flat_parts;
  for (const auto& t : tensors) flat_parts.push_back(t.detach().reshape({-1}).to(torch::kFloat32));
  // Gloo reduces host memory: a model on a GPU is averaged through one host copy per step.
  std::vector<at::Tensor> flat = {torch::cat(flat_parts).to(torch::kCPU)};
  collective(config_, "gradient all-reduce", [&] { impl_->group->allreduce(flat)->wait(); });
  flat[0].div_(config_.world_size);
  torch::NoGradGuard no_grad;
  int64_t offset = 0;
  for (const auto& t : tensors) {
    const int64_t n = t.numel();
    t.copy_(flat[0].slice(0, offset, offset + n).view(t.sizes()));
    offset += n;
  }
}

std::vector<double> ProcessGroup::sum(const std::vector<double>& values) {
  std::vector<at::Tensor> t = {torch::tensor(values, torch::kFloat64)};
  collective(config_, "all-reduce", [&] { impl_->group->allreduce(t)->wait(); });
  const auto a = t[0].accessor<double, 1>();
  std::vector<double> out(values.size());
  for (size_t i = 0; i < out.size(); ++i) out[i] = a[static_cast<int64_t>(i)];
  return out;
}

std::string ProcessGroup::share_from_rank0(const std::string& text) {
  const std::string key = "umvs/share/" + std::to_string(impl_->shared++);
  std::string result = text;
  collective(config_, "exchange with rank 0", [&] {
    if (config_.rank == 0) {
      impl_->store->set(key, std::vector<uint8_t>(text.begin(), text.end()));
    } else {
      const auto bytes = impl_->store->get(key);  // waits for rank 0 (store timeout)
      result.assign(bytes.begin(), bytes.end());
    }
  });
  return result;
}

#else  // no Gloo headers at build time

bool distributed_available() { return false; }

struct ProcessGroup::Impl {};

ProcessGroup::ProcessGroup(const DistributedConfig& config) : config_(config) {
  throw std::runtime_error("this build of unsup_mvs has no distributed training (c10d with Gloo): install the Gloo "
                           "headers (Debian: libgloo-dev) and rebuild");
}
ProcessGroup::~ProcessGroup() = default;
void ProcessGroup::broadcast_from_rank0(const std::vector<torch::Tensor>&) {}
void ProcessGroup::average(const std::vector<torch::Tensor>&) {}
std::vector<double> ProcessGroup::sum(const std::vector<double>& values) { return values; }
std::string ProcessGroup::share_from_rank0(const std::string& text) { return text; }

#endif

}  // namespace umvs
