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
#include "tjepa/layout/inspire.hpp"
#include "tjepa/layout/csv.hpp"

#include "tjepa/graph/taxel_graph.hpp"
#include "tjepa/graph/skin.hpp"
#include "tjepa/graph/bridges.hpp"
#include "tjepa/graph/coordinate_graphs.hpp"
#include "tjepa/graph/join.hpp"
#include "tjepa/graph/grouping.hpp"
#include "tjepa/graph/block_grouping.hpp"
#include "tjepa/graph/grow_grouping.hpp"
#include "tjepa/graph/colors.hpp"
#include "tjepa/graph/svg.hpp"

#include "tjepa/masks/collator.hpp"
#include "tjepa/masks/config.hpp"
#include "tjepa/masks/context.hpp"
#include "tjepa/masks/domain.hpp"
#include "tjepa/masks/global.hpp"
#include "tjepa/masks/ijepa_blocks.hpp"
#include "tjepa/masks/local.hpp"
#include "tjepa/masks/svg.hpp"

#include "tjepa/model/param_set.hpp"
