#include "unsup_mvs/core/weight_blend.h"

#include <cmath>
#include <stdexcept>
#include <string>

namespace umvs {

namespace {

std::string shape_of(const torch::Tensor& t) {
  std::string s;
  for (int64_t d : t.sizes()) s += (s.empty() ? "" : "x") + std::to_string(d);
  return "[" + s + "]";
}

// Throws unless both dictionaries name the same tensors with the same shapes.
void check_same_tensors(const torch::OrderedDict<std::string, torch::Tensor>& mine,
                        const torch::OrderedDict<std::string, torch::Tensor>& start, const char* kind) {
  if (mine.size() != start.size()) {
    throw std::invalid_argument(std::string("blend_weights: the models have ") + std::to_string(mine.size()) + " and " +
                                std::to_string(start.size()) + " " + kind + "s: not the same architecture");
  }
  for (const auto& item : mine) {
    const torch::Tensor* other = start.find(item.key());
    if (!other) {
      throw std::invalid_argument("blend_weights: " + std::string(kind) + " '" + item.key() +
                                  "' is missing from the starting model: not the same architecture");
    }
    if (!item.value().sizes().equals(other->sizes())) {
      throw std::invalid_argument("blend_weights: " + std::string(kind) + " '" + item.key() + "' is " +
                                  shape_of(item.value()) + " in one model and " + shape_of(*other) + " in the other");
    }
  }
}

void blend_tensors(torch::OrderedDict<std::string, torch::Tensor> mine,
                   const torch::OrderedDict<std::string, torch::Tensor>& start, double share) {
  for (auto& item : mine) {
    torch::Tensor& t = item.value();
    if (!t.is_floating_point()) continue;  // BatchNorm's step counter
    t.mul_(share).add_(start[item.key()].to(t.device(), t.scalar_type()), 1.0 - share);
  }
}

}  // namespace

void blend_weights(MvsNet& model, MvsNet& start, double share) {
  if (!(share >= 0.0 && share <= 1.0)) {
    throw std::invalid_argument("blend_weights: the adapted model's share must be in [0, 1], got " +
                                std::to_string(share));
  }
  if (model.ptr() == start.ptr()) return;  // a model blended with itself is itself
  torch::NoGradGuard no_grad;
  const auto params = model->named_parameters(), buffers = model->named_buffers();
  const auto start_params = start->named_parameters(), start_buffers = start->named_buffers();
  // Everything is checked before anything changes: a refused blend leaves the model as it was.
  check_same_tensors(params, start_params, "parameter");
  check_same_tensors(buffers, start_buffers, "buffer");
  blend_tensors(params, start_params, share);
  blend_tensors(buffers, start_buffers, share);
}

}  // namespace umvs
