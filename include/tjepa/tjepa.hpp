#pragma once
// tjepa: Tactile-JEPA for distributed tactile skins. This umbrella header only includes.
#include "tjepa/version.hpp"

#include "tjepa/core/aligned.hpp"
#include "tjepa/core/eigen.hpp"
#include "tjepa/core/error.hpp"
#include "tjepa/core/random.hpp"
#include "tjepa/core/atomic_write.hpp"

#include "tjepa/layout/taxel_layout.hpp"
#include "tjepa/layout/grid_pad.hpp"
#include "tjepa/layout/layout_builder.hpp"
#include "tjepa/layout/allegro_xela.hpp"
#include "tjepa/layout/generic.hpp"

#include "tjepa/data/grouped_gather.hpp"
#include "tjepa/data/labels.hpp"
#include "tjepa/data/named_tensor.hpp"
#include "tjepa/data/npy.hpp"
#include "tjepa/data/preprocessor.hpp"
#include "tjepa/data/recording.hpp"
#include "tjepa/data/simulated_dataset.hpp"
#include "tjepa/data/simulated_skin.hpp"
#include "tjepa/data/text_reader.hpp"
#include "tjepa/data/window.hpp"
#include "tjepa/data/window_source.hpp"

#include "tjepa/graph/taxel_graph.hpp"
#include "tjepa/graph/skin.hpp"
#include "tjepa/graph/bridges.hpp"
#include "tjepa/graph/colors.hpp"
#include "tjepa/graph/svg.hpp"

#include "tjepa/model/param_set.hpp"
