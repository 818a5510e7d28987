// Precompiled header for every target that uses LibTorch (see CMakeLists.txt). Not for inclusion.
#pragma once
#include <torch/torch.h>
