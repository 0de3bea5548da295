#pragma once
// The built-in default data in one call: a simulated skin over a layout, recorded into a training
// and a validation recording (the same sensor, later in time), with the magnetic preprocessing
// fitted on a contact-free baseline recording and the training recording only.
//
//   auto data = simulate_dataset(layouts::allegro_xela().layout, {}, seed);
//   data.train.gather(ids, batch);               // [B, 368, 10, 3], standardized, with labels
//   checkpoint.add(data.preprocessor.state());   // the fitted statistics travel with the model
#include <cstdint>

#include "tjepa/core/error.hpp"
#include "tjepa/data/preprocessor.hpp"
#include "tjepa/sim/simulated_skin.hpp"
#include "tjepa/data/window.hpp"
#include "tjepa/data/window_source.hpp"
#include "tjepa/layout/taxel_layout.hpp"

namespace tjepa {

struct SimulatedDatasetOptions {
  int train_windows = 20000;
  int validation_windows = 2000;
  int baseline_frames = 1000;  // contact-free frames for the preprocessing baseline
  WindowSpec window{10, 0};    // τ = 10, non-overlapping (Sparsh-skin)
  SimConfig sim{};
};

struct SimulatedDataset {
  WindowSource train;
  WindowSource validation;
  Preprocessor preprocessor;  // fitted on the baseline and training recordings only
};

inline SimulatedDataset simulate_dataset(const TaxelLayout& layout, const SimulatedDatasetOptions& opt = {},
                                         std::uint64_t seed = 0) {
  opt.window.validate();
  require<ConfigError>(opt.train_windows > 0 && opt.validation_windows > 0 && opt.baseline_frames > 0,
                       "simulate_dataset: train_windows = ", opt.train_windows, ", validation_windows = ",
                       opt.validation_windows, ", baseline_frames = ", opt.baseline_frames, ", expected all > 0");
  SimulatedSkin sim(layout, opt.sim, seed);
  PreprocessConfig cfg;
  if (opt.sim.raw_counts) {
    cfg = PreprocessConfig::xela_counts();
  } else {
    cfg.scaling = Scaling::per_axis;  // no offsets to remove
  }
  Preprocessor pre(cfg);
  const Recording baseline = sim.record_baseline(opt.baseline_frames);
  if (cfg.subtract_baseline) pre.fit_baseline(baseline);
  auto frames = [&](int windows) {
    return (windows - 1) * opt.window.step() + opt.window.length;
  };
  SimRecording train = sim.record(frames(opt.train_windows));
  SimRecording validation = sim.record(frames(opt.validation_windows));
  train.recording.set_source("simulated skin (train)");
  validation.recording.set_source("simulated skin (validation)");
  pre.fit(train.recording);
  return SimulatedDataset{WindowSource(std::move(train.recording), opt.window, std::move(train.labels), pre),
                          WindowSource(std::move(validation.recording), opt.window, std::move(validation.labels), pre),
                          pre};
}

}  // namespace tjepa
