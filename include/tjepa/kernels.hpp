#pragma once
// tjepa's compute kernels, for calling or micro-benchmarking them directly: everything here is in
// tjepa::kernels, each kernel with a plain scalar reference in tjepa::kernels::ref. The model's
// modules (tjepa/model/) are built on them; <tjepa/tjepa.hpp> does not name them.
#include "tjepa/kernels/attention.hpp"
#include "tjepa/kernels/drop_path.hpp"
#include "tjepa/kernels/gather.hpp"
#include "tjepa/kernels/gelu.hpp"
#include "tjepa/kernels/layer_norm.hpp"
#include "tjepa/kernels/linear.hpp"
#include "tjepa/kernels/peaks.hpp"
#include "tjepa/kernels/softmax.hpp"
#include "tjepa/kernels/conv2d.hpp"
