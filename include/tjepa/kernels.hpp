#pragma once
// tjepa's compute kernels, for calling or micro-benchmarking them directly: everything here is in
// tjepa::kernels, each kernel with a plain scalar reference in tjepa::kernels::ref. The model's
// modules (tjepa/model/) are built on them; <tjepa/tjepa.hpp> does not name them.
#include "tjepa/model/kernels/attention.hpp"
#include "tjepa/model/kernels/drop_path.hpp"
#include "tjepa/model/kernels/gather.hpp"
#include "tjepa/model/kernels/gelu.hpp"
#include "tjepa/model/kernels/layer_norm.hpp"
#include "tjepa/model/kernels/linear.hpp"
#include "tjepa/model/kernels/softmax.hpp"
#include "tjepa/model/kernels/conv2d.hpp"
