#pragma once
// The paper's evaluation protocol as an application of the library (Tactile-JEPA, Sec. IV-B,
// IV-C and V): on the simulated Allegro hand, object classification, 3-axis force and in-hand
// pose; the rows constant, ridge, random, end to end, MAE and Tactile-JEPA; pre-training caches;
// tables with Welch tests; the mask ablation (run_grasp_eval, `tjepa eval`, `tjepa demo`).
#include "tjepa/sim.hpp"
#include "tjepa/baselines.hpp"

#include "tjepa/eval/grasp_tasks.hpp"
#include "tjepa/eval/pretrain_cache.hpp"
#include "tjepa/eval/grasp_eval.hpp"
