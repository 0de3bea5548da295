#pragma once
// tjepa: Tactile-JEPA for distributed tactile skins. This umbrella header only includes.
#include "tjepa/version.hpp"

#include "tjepa/core/aligned.hpp"
#include "tjepa/core/eigen.hpp"
#include "tjepa/core/error.hpp"
#include "tjepa/core/random.hpp"

#include "tjepa/graph/taxel_graph.hpp"

#include "tjepa/model/kernels/attention.hpp"
#include "tjepa/model/param_set.hpp"
