#pragma once
// The paper's baselines, each through the same Trainer as Tactile-JEPA: MAE (masked taxel
// reconstruction), DINO (Sparsh-skin's self-distillation, with its head and losses) and BYOL
// (T-DEX's tactile images through AlexNet, with its projector and predictor). A robot codebase
// that runs the Tactile-JEPA encoder includes <tjepa/tjepa.hpp> only and gets none of these.
#include "tjepa/tjepa.hpp"

#include "tjepa/baselines/mae.hpp"

#include "tjepa/baselines/dino_head.hpp"
#include "tjepa/baselines/dino_loss.hpp"
#include "tjepa/baselines/dino.hpp"

#include "tjepa/baselines/taxel_image.hpp"
#include "tjepa/baselines/alexnet.hpp"
#include "tjepa/baselines/projection_mlp.hpp"
#include "tjepa/baselines/byol.hpp"
