#pragma once
// tjepa: Tactile-JEPA for distributed tactile skins. This umbrella header includes the
// algorithm's user-facing headers, in the order of the data's path: layouts, graph, sensors,
// data, masks, model, optim, io, train (every objective through one Trainer, the reference
// code's checkpoints), and the generic downstream pieces (heads, ridge, metrics, Welch tests).
// Four other umbrellas stand beside it:
//   <tjepa/kernels.hpp>    the compute kernels under the modules (tjepa::kernels), for those who
//                          call or benchmark them directly
//   <tjepa/baselines.hpp>  the paper's baselines: MAE, DINO and BYOL with their modules (AlexNet,
//                          DINO's head, BYOL's projector, tactile images)
//   <tjepa/sim.hpp>        the simulated skins and the simulated Allegro hand (test data)
//   <tjepa/eval.hpp>       the paper's evaluation protocol on the simulated hand (grasp tasks,
//                          run_grasp_eval, its tables and caches), which the `tjepa` command uses
// No header reachable from this one includes baselines/, sim/ or eval/ (tests/check_layers.cmake).

#include "tjepa/version.hpp"

#include "tjepa/core/aligned.hpp"
#include "tjepa/core/eigen.hpp"
#include "tjepa/core/error.hpp"
#include "tjepa/core/random.hpp"
#include "tjepa/core/atomic_write.hpp"
#include "tjepa/core/files.hpp"
#include "tjepa/core/json.hpp"
#include "tjepa/core/param_set.hpp"
#include "tjepa/core/prefixed_params.hpp"
#include "tjepa/core/threads.hpp"

#include "tjepa/layout/taxel_layout.hpp"

#include "tjepa/graph/taxel_graph.hpp"
#include "tjepa/graph/skin.hpp"
#include "tjepa/graph/bridges.hpp"
#include "tjepa/graph/coordinate_graphs.hpp"
#include "tjepa/graph/join.hpp"
#include "tjepa/graph/grouping.hpp"
#include "tjepa/graph/block_grouping.hpp"
#include "tjepa/graph/grow_grouping.hpp"
#include "tjepa/graph/colors.hpp"
#include "tjepa/graph/spectral_positions.hpp"
#include "tjepa/graph/svg.hpp"

#include "tjepa/sensors/grid_pad.hpp"
#include "tjepa/sensors/layout_builder.hpp"
#include "tjepa/sensors/allegro_xela.hpp"
#include "tjepa/sensors/generic.hpp"
#include "tjepa/sensors/inspire.hpp"
#include "tjepa/sensors/csv.hpp"
#include "tjepa/sensors/skin_from_coordinates.hpp"

#include "tjepa/data/drift_tracker.hpp"
#include "tjepa/data/grouped_gather.hpp"
#include "tjepa/data/labels.hpp"
#include "tjepa/data/named_tensor.hpp"
#include "tjepa/data/npy.hpp"
#include "tjepa/data/preprocessor.hpp"
#include "tjepa/data/recording.hpp"
#include "tjepa/data/text_reader.hpp"
#include "tjepa/data/trial_table.hpp"
#include "tjepa/data/window.hpp"
#include "tjepa/data/window_source.hpp"

#include "tjepa/masks/collator.hpp"
#include "tjepa/masks/config.hpp"
#include "tjepa/masks/context.hpp"
#include "tjepa/masks/domain.hpp"
#include "tjepa/masks/global.hpp"
#include "tjepa/masks/ijepa_blocks.hpp"
#include "tjepa/masks/local.hpp"
#include "tjepa/masks/svg.hpp"
#include "tjepa/masks/uniform_masking.hpp"
#include "tjepa/masks/workspace.hpp"

#include "tjepa/kernels/peaks.hpp"
#include "tjepa/kernels/precision.hpp"

#include "tjepa/model/attention.hpp"
#include "tjepa/model/attentive_probe.hpp"
#include "tjepa/model/block.hpp"
#include "tjepa/model/encoder.hpp"
#include "tjepa/model/init.hpp"
#include "tjepa/model/layers.hpp"
#include "tjepa/model/mlp.hpp"
#include "tjepa/model/position_table.hpp"
#include "tjepa/model/predictor.hpp"
#include "tjepa/model/stage_clock.hpp"
#include "tjepa/model/taxel_pooling.hpp"
#include "tjepa/model/tokenizer.hpp"
#include "tjepa/model/workspace.hpp"

#include "tjepa/optim/adamw.hpp"
#include "tjepa/optim/clip.hpp"
#include "tjepa/optim/ema.hpp"
#include "tjepa/optim/schedule.hpp"

#include "tjepa/io/checkpoint.hpp"
#include "tjepa/io/safetensors.hpp"

#include "tjepa/train/health.hpp"
#include "tjepa/train/jepa_model.hpp"
#include "tjepa/train/jepa_step.hpp"
#include "tjepa/train/loss.hpp"
#include "tjepa/train/config.hpp"
#include "tjepa/train/trained_model.hpp"
#include "tjepa/train/reference_checkpoint.hpp"
#include "tjepa/train/objective.hpp"
#include "tjepa/train/trainer.hpp"
#include "tjepa/train/jepa_objective.hpp"

#include "tjepa/downstream/causal_attention.hpp"
#include "tjepa/downstream/cross_entropy.hpp"
#include "tjepa/downstream/embed.hpp"
#include "tjepa/downstream/features.hpp"
#include "tjepa/downstream/metrics.hpp"
#include "tjepa/downstream/early_stopping.hpp"
#include "tjepa/downstream/probe_head.hpp"
#include "tjepa/downstream/head_file.hpp"
#include "tjepa/downstream/pipeline.hpp"
#include "tjepa/downstream/probe_labels.hpp"
#include "tjepa/downstream/sequence_head.hpp"
#include "tjepa/downstream/ridge.hpp"
#include "tjepa/downstream/score_table.hpp"
#include "tjepa/downstream/trial_split.hpp"
#include "tjepa/downstream/welch.hpp"
