#include "unsup_mvs/io/checkpoint.h"

#include <torch/serialize.h>
#include <torch/torch.h>

#include <cstring>
#include <set>
#include <sstream>
#include <stdexcept>

#include "unsup_mvs/io/atomic_file.h"
#include "unsup_mvs/io/input_limits.h"

namespace umvs {

namespace {

constexpr const char* kFormatKey = "unsup_mvs_checkpoint";
constexpr int64_t kFormatVersion = 1;

torch::Tensor bytes_to_tensor(const std::string& bytes) {
  auto t = torch::empty({static_cast<int64_t>(bytes.size())}, torch::kUInt8);
  if (!bytes.empty()) std::memcpy(t.data_ptr(), bytes.data(), bytes.size());
  return t;
}

std::string tensor_to_bytes(const torch::Tensor& t) {
  auto c = t.contiguous();
  return std::string(static_cast<const char*>(c.data_ptr()), c.numel());
}

c10::impl::GenericDict config_to_dict(const MvsNetConfig& c) {
  c10::impl::GenericDict d(c10::StringType::get(), c10::AnyType::get());
  d.insert("network", std::string(to_string(c.network)));
  d.insert("num_depth", static_cast<int64_t>(c.num_depth));
  d.insert("depth_sampling", std::string(to_string(c.depth_sampling)));
  d.insert("refine", c.refine);
  d.insert("num_views", static_cast<int64_t>(c.num_views));
  d.insert("input_normalization", std::string(to_string(c.input_normalization)));
  d.insert("feature_warp", std::string(to_string(c.feature_warp)));
  return d;
}

MvsNetConfig config_from_dict(const c10::impl::GenericDict& d, const std::string& path) {
  MvsNetConfig c;
  try {
    // Checkpoints written before the field existed are MVSNet's.
    if (d.contains("network")) c.network = network_kind_from_string(d.at("network").toStringRef());
    c.num_depth = static_cast<int>(d.at("num_depth").toInt());
    c.depth_sampling = depth_sampling_from_string(d.at("depth_sampling").toStringRef());
    c.refine = d.at("refine").toBool();
    c.num_views = static_cast<int>(d.at("num_views").toInt());
    // Checkpoints written before the field existed were trained on raw [0,1] images.
    if (d.contains("input_normalization")) {
      c.input_normalization = input_normalization_from_string(d.at("input_normalization").toStringRef());
    }
    // Those written before this field were trained with MVSNet_pytorch's warp.
    c.feature_warp = d.contains("feature_warp") ? feature_warp_from_string(d.at("feature_warp").toStringRef())
                                                : FeatureWarp::kMvsNetPytorch;
  } catch (const std::exception& e) {
    throw std::runtime_error("checkpoint '" + path + "': malformed network config");
  }
  return c;
}

// A model whose weights hold NaN or infinity produces NaN depth maps: refuse it by name.
void check_finite_weights(torch::nn::Module& module, const std::string& path) {
  for (const auto& named : {module.named_parameters(), module.named_buffers()}) {
    for (const auto& t : named) {
      if (!t.value().is_floating_point()) continue;
      const int64_t bad = t.value().numel() - torch::isfinite(t.value()).sum().item<int64_t>();
      if (bad > 0) {
        throw std::runtime_error("'" + path + "' is a broken model: tensor '" + t.key() + "' has " + std::to_string(bad) +
                                 " non-finite values (NaN or infinity)");
      }
    }
  }
}

}  // namespace

void load_state_dict(torch::nn::Module& module, const c10::impl::GenericDict& dict, const std::string& source) {
  std::map<std::string, torch::Tensor> expected;
  for (const auto& p : module.named_parameters()) expected[p.key()] = p.value();
  for (const auto& b : module.named_buffers()) expected[b.key()] = b.value();
  std::vector<std::string> problems;
  std::set<std::string> seen;
  torch::NoGradGuard no_grad;
  for (const auto& entry : dict) {
    const std::string name = entry.key().toStringRef();
    auto it = expected.find(name);
    if (it == expected.end()) {
      problems.push_back("unexpected tensor '" + name + "'");
      continue;
    }
    seen.insert(name);
    if (!entry.value().isTensor()) {
      problems.push_back("'" + name + "' is not a tensor");
      continue;
    }
    const auto value = entry.value().toTensor();
    if (value.sizes() != it->second.sizes()) {
      std::ostringstream os;
      os << "'" << name << "' has shape " << value.sizes() << ", the network needs " << it->second.sizes();
      problems.push_back(os.str());
      continue;
    }
    it->second.copy_(value);
  }
  for (const auto& e : expected) {
    if (!seen.count(e.first)) problems.push_back("missing tensor '" + e.first + "'");
  }
  if (!problems.empty()) {
    std::ostringstream os;
    os << "'" << source << "' does not fit the network (" << problems.size() << " problems):";
    for (size_t i = 0; i < problems.size() && i < 20; ++i) os << "\n  " << problems[i];
    if (problems.size() > 20) os << "\n  ...";
    throw std::runtime_error(os.str());
  }
}

void save_checkpoint(const std::string& path, MvsNet& model, const CheckpointMeta& meta) {
  c10::impl::GenericDict weights(c10::StringType::get(), c10::TensorType::get());
  for (const auto& p : model->named_parameters()) weights.insert(p.key(), p.value().detach().to(torch::kCPU).contiguous());
  for (const auto& b : model->named_buffers()) weights.insert(b.key(), b.value().detach().to(torch::kCPU).contiguous());
  c10::impl::GenericDict metrics(c10::StringType::get(), c10::FloatType::get());
  for (const auto& m : meta.metrics) metrics.insert(m.first, m.second);
  c10::impl::GenericDict root(c10::StringType::get(), c10::AnyType::get());
  root.insert(kFormatKey, kFormatVersion);
  root.insert("config", config_to_dict(model->config()));
  root.insert("model", weights);
  root.insert("step", meta.step);
  root.insert("optimizer", bytes_to_tensor(meta.optimizer_state));
  root.insert("rng", bytes_to_tensor(meta.rng_state));
  root.insert("metrics", metrics);
  const std::vector<char> bytes = torch::pickle_save(c10::IValue(root));
  write_file_atomically(path, [&](std::ostream& out) { out.write(bytes.data(), static_cast<std::streamsize>(bytes.size())); });
}

LoadedModel load_model(const std::string& path, const torch::Device& device, const MvsNetConfig* expected) {
  const std::string raw = read_bounded_file(path, kMaxCheckpointBytes, "model file");
  if (raw.compare(0, 2, "PK") == 0) verify_zip_archive(raw, path);
  c10::IValue value;
  try {
    value = torch::pickle_load(std::vector<char>(raw.begin(), raw.end()));
  } catch (const std::exception& e) {
    std::string why = e.what();
    why = why.substr(0, why.find('\n'));
    throw std::runtime_error("'" + path + "' is not a readable model file (corrupt or not a torch file): " + why);
  }
  if (!value.isGenericDict()) throw std::runtime_error("'" + path + "' is not a model file (no dictionary inside)");
  const auto root = value.toGenericDict();
  LoadedModel out;
  MvsNetConfig config = expected ? *expected : MvsNetConfig();
  c10::impl::GenericDict weights = root;
  if (root.contains(kFormatKey)) {
    out.format = "unsup_mvs";
    const int64_t version = root.at(kFormatKey).toInt();
    if (version > kFormatVersion) {
      throw std::runtime_error("checkpoint '" + path + "' has format version " + std::to_string(version) +
                               ", newer than this build understands (" + std::to_string(kFormatVersion) + ")");
    }
    config = config_from_dict(root.at("config").toGenericDict(), path);
    if (expected) {
      const std::string mismatch = expected->architecture_mismatch(config);
      if (!mismatch.empty()) throw std::runtime_error("checkpoint '" + path + "' does not fit: " + mismatch);
    }
    weights = root.at("model").toGenericDict();
    out.meta.step = root.at("step").toInt();
    out.meta.optimizer_state = tensor_to_bytes(root.at("optimizer").toTensor());
    out.meta.rng_state = tensor_to_bytes(root.at("rng").toTensor());
    for (const auto& m : root.at("metrics").toGenericDict()) out.meta.metrics[m.key().toStringRef()] = m.value().toDouble();
  } else {
    out.format = "mvsnet_pytorch";
    // Their files carry no config: read them as MVSNet_pytorch runs them (and as the parity vectors were made).
    if (!expected) config.feature_warp = FeatureWarp::kMvsNetPytorch;
  }
  out.model = MvsNet(config);
  load_state_dict(*out.model, weights, path);
  check_finite_weights(*out.model, path);
  out.model->to(device);
  out.model->eval();
  return out;
}

}  // namespace umvs
