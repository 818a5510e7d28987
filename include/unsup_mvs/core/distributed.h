// Data-parallel training over PyTorch's c10d: N processes ("ranks") each compute the gradient of
// their share of a step's tuples, the gradients are averaged (all-reduce), and every rank applies
// the same update, so that all ranks hold the same weights. Rendezvous through a TCPStore on rank
// 0's MASTER_ADDR:MASTER_PORT, as torchrun does; transport Gloo (CPU tensors, and CUDA tensors
// through host copies when the LibTorch has no NCCL).
#pragma once

#include <torch/types.h>

#include <memory>
#include <string>
#include <vector>

namespace umvs {

struct DistributedConfig {
  int world_size = 1;                   // processes in the job (1 = not distributed)
  int rank = 0;                         // this process, 0 .. world_size-1; rank 0 hosts the store
  std::string master_addr = "127.0.0.1";
  int master_port = 29500;
  double timeout_seconds = 120;         // rendezvous and each collective; a dead peer ends it sooner
  bool enabled() const { return world_size > 1; }
  void validate() const;  // throws std::invalid_argument naming the field
};

// The torchrun variables WORLD_SIZE, RANK, MASTER_ADDR, MASTER_PORT over `base` (those unset keep
// base's values). Throws std::invalid_argument naming a variable that is not a number.
DistributedConfig distributed_config_from_environment(DistributedConfig base = {});

// Whether this build can run a distributed job (c10d with Gloo headers at build time).
bool distributed_available();

// One rank's membership of the job. Construction blocks until all ranks have joined (or throws
// std::runtime_error after timeout_seconds naming the master address); every collective must be
// called by all ranks in the same order. A collective that fails because a peer died throws
// std::runtime_error naming the rank and the peer failure.
class ProcessGroup {
 public:
  explicit ProcessGroup(const DistributedConfig& config);
  ~ProcessGroup();
  int rank() const { return config_.rank; }
  int size() const { return config_.world_size; }

  // Every tensor in place becomes rank 0's value.
  void broadcast_from_rank0(const std::vector<torch::Tensor>& tensors);
  // Every tensor in place becomes the mean over the ranks (float tensors; one flat all-reduce).
  void average(const std::vector<torch::Tensor>& tensors);
  // The sums over the ranks of a few numbers.
  std::vector<double> sum(const std::vector<double>& values);
  // Rank 0 tells the others a text (e.g. "" to go on, or the reason it refused the run).
  std::string share_from_rank0(const std::string& text);

 private:
  struct Impl;
  DistributedConfig config_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace umvs
