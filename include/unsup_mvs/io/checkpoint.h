// Model files.
//  * Our checkpoint: one file (torch pickle, readable with torch.load in Python) holding the
//    network config, the weights and, for training, the optimiser state, the step, the RNG state
//    and metrics. A checkpoint never loads into a network of another shape silently.
//  * MVSNet_pytorch weights (a plain state dict, e.g. ../shared/data/mvsnet_parity/): imported by
//    name and shape; any missing, extra or mis-shaped tensor is an error naming it.
#pragma once

#include <map>
#include <string>

#include "unsup_mvs/core/mvsnet.h"

namespace umvs {

struct CheckpointMeta {
  int64_t step = 0;
  std::string optimizer_state;  // serialised torch::optim archive (empty: none)
  std::string rng_state;        // serialised generator state (empty: none)
  std::map<std::string, double> metrics;
};

// Atomic: a failed save leaves an existing file at `path` untouched.
void save_checkpoint(const std::string& path, MvsNet& model, const CheckpointMeta& meta = {});

struct LoadedModel {
  MvsNet model{nullptr};
  CheckpointMeta meta;
  std::string format;  // "unsup_mvs" or "mvsnet_pytorch"
};

// Loads either format (detected from the content) onto `device`, in eval() mode.
// `expected` (optional) is the architecture the caller needs; a checkpoint of another
// architecture is refused with a message naming the mismatch. For MVSNet_pytorch weights, which
// carry no config, `expected` gives the config, else the defaults with MVSNet_pytorch's feature
// warp. Our checkpoints written before the feature warp was saved read as MVSNet_pytorch's too.
// Throws std::runtime_error naming the file for a missing or unfitting file, one that is not a
// regular file or larger than kMaxCheckpointBytes (io/input_limits.h), a damaged one (zip CRC
// mismatch, unreadable pickle) and a model with NaN or infinite weights.
LoadedModel load_model(const std::string& path, const torch::Device& device,
                       const MvsNetConfig* expected = nullptr);

// Copies a name -> tensor dictionary into the module's parameters and buffers. Throws
// std::runtime_error listing missing, unexpected and mis-shaped entries; `source` names the file.
void load_state_dict(torch::nn::Module& module, const c10::impl::GenericDict& dict, const std::string& source);

}  // namespace umvs
