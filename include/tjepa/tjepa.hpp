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

#include "tjepa/model/attention.hpp"
#include "tjepa/model/attentive_probe.hpp"
#include "tjepa/model/block.hpp"
#include "tjepa/model/encoder.hpp"
#include "tjepa/model/init.hpp"
#include "tjepa/model/kernels/drop_path.hpp"
#include "tjepa/model/kernels/gather.hpp"
#include "tjepa/model/kernels/gelu.hpp"
#include "tjepa/model/kernels/layer_norm.hpp"
#include "tjepa/model/kernels/linear.hpp"
#include "tjepa/model/kernels/softmax.hpp"
#include "tjepa/model/layers.hpp"
#include "tjepa/model/mlp.hpp"
#include "tjepa/model/position_table.hpp"
#include "tjepa/model/predictor.hpp"
#include "tjepa/model/tokenizer.hpp"
#include "tjepa/model/workspace.hpp"
