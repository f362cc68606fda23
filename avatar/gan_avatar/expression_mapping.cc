#include "avatar/gan_avatar/expression_mapping.h"

#include <torch/torch.h>

namespace headforge {

ExpressionMappingImpl::ExpressionMappingImpl(int64_t expressions, int64_t w_dim, int64_t hidden) {
  mlp_ = register_module("mlp", nn::Mlp(std::vector<int64_t>{expressions, hidden, hidden, w_dim}));
}

}  // namespace headforge
