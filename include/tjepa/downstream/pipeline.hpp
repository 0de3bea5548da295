#pragma once
// Pipeline: a frozen encoder (and optionally a trained probe head) on a live stream of frames, one
// frame at a time, as a control loop calls it.
//
//   Pipeline p(load_trained_model("run.safetensors"), load_probe_head<float>("head.safetensors"),
//              {.column = skin.layout.column});
//   for (;;) if (const PipelineOutput* o = p.push(frame)) act(o->outputs);   // frame [N, m]
//
// Each push(frame):
//   frame [N, m] in the recording's column order  → layout order (TaxelLayout::column)
//   → drift tracking (the run's DriftTracker::step, if it tracked drift) → preprocessing (the run's
//   Preprocessor) → ring of the last τ frames [τ, N, m]
// and once τ frames have arrived, every `stride` frames:
//   window [N, m·τ] (oldest frame first, axis-major, as data/window_source.hpp's windows_to_tokens)
//   → tokenizer → encoder (target or context) → embedding [N, d]
//   → (head) + centring shift → probe → outputs [R + C]: regressions in their units (z·std + mean),
//     then class probabilities (softmax), and the most likely class.
// These are the windows a WindowSource cuts from the same recording with WindowSpec{τ, stride}
// after TrainedModel::track, so a head gives on a stream what `tjepa probe` gives on its windows.
//
// Nothing is allocated after the first window: every buffer is sized in the constructor, the
// workspaces stop growing on the first window, and the weights are packed once (frozen).
// restart() begins a new window (after a gap in the stream: the next window is never built from
// frames on both sides of it); reset() also restarts drift tracking from the fitted rest readings.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "tjepa/core/aligned.hpp"
#include "tjepa/core/error.hpp"
#include "tjepa/downstream/head_file.hpp"
#include "tjepa/kernels/precision.hpp"
#include "tjepa/model/stage_clock.hpp"
#include "tjepa/model/workspace.hpp"
#include "tjepa/train/trained_model.hpp"

namespace tjepa {

struct PipelineConfig {
  // TaxelLayout::column of the model's layout: column[i] is the recording's column of layout taxel
  // i. Frames come in and embeddings go out in the recording's order. Empty: the layout's order.
  std::vector<int> column;
  int stride = 0;                  // frames between windows; 0: the head's (1 without a head)
  bool target_encoder = true;      // the EMA target encoder (the paper's), or the context encoder
  Precision precision = Precision::fp32;  // of the encoder's products (the head's are fp32)
  bool frozen_weights = true;      // pack the weights once (false: on every window, as training does)
  StageClock* clock = nullptr;     // times the stages of each window (window, tokenizer, blocks, probe)
};

// What a completed window gives. Spans point into the pipeline and stay valid until the next push.
struct PipelineOutput {
  std::int64_t frame = 0;           // index of the window's last frame (frames pushed since reset, − 1)
  std::span<const float> embedding; // [N, d] in the recording's column order
  std::span<const float> outputs;   // [R + C]: regressions in their units, then class probabilities
  int label = -1;                   // most likely class (−1 without classes)
};

class Pipeline {
 public:
  Pipeline(TrainedModel model, std::optional<LoadedProbeHead<float>> head = std::nullopt, PipelineConfig config = {})
      : m_(std::move(model)), head_(std::move(head)), cfg_(std::move(config)) {
    require<ConfigError>(m_.model != nullptr, "Pipeline: no model");
    const JepaModel<float>& jm = *m_.model;
    require<ConfigError>(jm.config.group_size.empty(), "Pipeline: the model has a grouped tokenizer (",
                         jm.config.group_size.size(), " groups); the pipeline reads one token per taxel");
    N_ = jm.num_tokens();
    d_ = jm.dim();
    tau_ = m_.config.data.tau;
    require<ConfigError>(tau_ > 0 && jm.config.in_dim % tau_ == 0, "Pipeline: the model's token width ",
                         jm.config.in_dim, " is not tau = ", tau_, " frames of whole readings");
    axes_ = jm.config.in_dim / tau_;
    require<ConfigError>(cfg_.stride >= 0, "Pipeline: stride = ", cfg_.stride, ", expected >= 0");
    if (!cfg_.column.empty()) {
      require<ShapeError>(static_cast<int>(cfg_.column.size()) == N_, "Pipeline: column has ", cfg_.column.size(),
                          " entries, the model has ", N_, " taxels");
      std::vector<char> seen(static_cast<std::size_t>(N_), 0);
      for (std::size_t i = 0; i < cfg_.column.size(); ++i) {
        const int c = cfg_.column[i];
        require<ConfigError>(c >= 0 && c < N_ && !seen[static_cast<std::size_t>(c)], "Pipeline: column[", i, "] = ", c,
                             ", expected each column of [0, ", N_, ") once");
        seen[static_cast<std::size_t>(c)] = 1;
      }
    }
    if (m_.pre.config().scaling != Scaling::none || m_.pre.config().subtract_baseline)
      require<ConfigError>(m_.pre.ready(), "Pipeline: the model's preprocessing has no fitted statistics");
    const ParamSet<float>& enc = encoder_params();
    if (head_) {
      const HeadInfo& info = head_->info;
      const ProbeHead<float>& h = head_->head;
      require<ConfigError>(h.probe.config.dim == d_, "Pipeline: the head reads embeddings of width ",
                           h.probe.config.dim, ", the encoder's are ", d_);
      require<ConfigError>(info.tau == tau_, "Pipeline: the head was trained on windows of ", info.tau,
                           " frames, the model's are ", tau_);
      require<ConfigError>(info.center_shift.empty() || info.center_shift.size() == static_cast<std::size_t>(N_) * d_,
                           "Pipeline: the head's centring shift has ", info.center_shift.size(), " values, expected ",
                           N_, " x ", d_);
      if (!info.encoder.empty()) {
        const std::string here = encoder_fingerprint(m_, enc);
        if (here != info.encoder) {
          const std::string other = encoder_fingerprint(m_, cfg_.target_encoder ? jm.context : jm.target);
          fail<ConfigError>("Pipeline: the head was trained on encoder ", info.encoder,
                            info.encoder_file.empty() ? std::string() : " (" + info.encoder_file + ")", ", this is ",
                            cfg_.target_encoder ? "the target" : "the context", " encoder ", here,
                            other == info.encoder ? std::string("; the head reads the model's ") +
                                                        (cfg_.target_encoder ? "context" : "target") + " encoder"
                                                  : std::string());
        }
      }
      if (cfg_.stride == 0) cfg_.stride = info.stride;
      outputs_.assign(static_cast<std::size_t>(h.outputs()), 0.0f);
      shifted_.assign(static_cast<std::size_t>(N_) * d_, 0.0f);
    }
    if (cfg_.stride == 0) cfg_.stride = 1;
    const std::size_t frame = static_cast<std::size_t>(N_) * axes_;
    ring_.assign(static_cast<std::size_t>(tau_) * frame, 0.0f);
    window_.assign(ring_.size(), 0.0f);
    tokens_.assign(static_cast<std::size_t>(N_) * d_, 0.0f);
    emb_.assign(tokens_.size(), 0.0f);
    if (!cfg_.column.empty()) out_emb_.assign(tokens_.size(), 0.0f);
    ws_.frozen_weights = cfg_.frozen_weights;
    ws_.precision = cfg_.precision;
    ws_.clock = cfg_.clock;
    head_ws_.frozen_weights = cfg_.frozen_weights;
    reset();
  }

  int taxels() const { return N_; }
  int axes() const { return axes_; }
  int tau() const { return tau_; }
  int stride() const { return cfg_.stride; }
  int dim() const { return d_; }
  int outputs() const { return head_ ? head_->head.outputs() : 0; }
  const TrainedModel& model() const { return m_; }
  const std::optional<LoadedProbeHead<float>>& head() const { return head_; }
  std::int64_t frames() const { return frames_; }  // pushed since reset()

  // A new window begins with the next frame: after a gap, the frames before it are never mixed
  // with the frames after. Drift tracking carries on.
  void restart() {
    filled_ = 0;
    since_ = 0;
  }
  // restart(), and drift tracking back to the fitted rest readings (another session of the sensor).
  void reset() {
    restart();
    frames_ = 0;
    if (m_.drift) m_.drift->reset();
  }

  // One frame [N, m] in the recording's column order. Returns the window's output when this frame
  // completes one (nullptr otherwise). A frame with a wrong size or a non-finite reading (that the
  // preprocessing does not take as a drop-out) throws DataError and leaves the pipeline as it was.
  const PipelineOutput* push(std::span<const float> frame) {
    const std::size_t per = static_cast<std::size_t>(N_) * axes_;
    require<ShapeError>(frame.size() == per, "Pipeline::push: a frame of ", frame.size(), " values, expected ", N_,
                        " taxels x ", axes_, " axes = ", per);
    const bool nan_ok = m_.pre.config().nan_as_dropout;
    for (std::size_t k = 0; k < per; ++k)
      if (!std::isfinite(frame[k]) && !(nan_ok && std::isnan(frame[k])))
        fail<DataError>("Pipeline::push: frame ", frames_, ": column ", k / static_cast<std::size_t>(axes_), " axis ",
                        k % static_cast<std::size_t>(axes_), " reads ", frame[k], ", expected a finite value");
    // Straight into the ring slot, in the layout's order (the layout's taxel i reads the
    // recording's column column[i]), then drift tracking and preprocessing in place: the frame
    // was checked above, so nothing below throws and a refused frame leaves the ring as it was.
    float* slot = ring_.data() + static_cast<std::size_t>(head_slot_) * per;
    if (cfg_.column.empty()) {
      std::copy(frame.begin(), frame.end(), slot);
    } else {
      for (int i = 0; i < N_; ++i)
        std::copy_n(frame.data() + static_cast<std::size_t>(cfg_.column[static_cast<std::size_t>(i)]) * axes_, axes_,
                    slot + static_cast<std::size_t>(i) * axes_);
    }
    if (m_.drift) m_.drift->step(slot);
    if (m_.pre.ready()) m_.pre.apply(slot, 1, N_, 1, axes_);
    head_slot_ = (head_slot_ + 1) % tau_;
    ++frames_;
    filled_ = std::min(filled_ + 1, tau_);
    if (filled_ < tau_) return nullptr;
    // The first window ends at its τ-th frame, then one every stride frames.
    if (since_++ % cfg_.stride != 0) return nullptr;
    run_window();
    return &out_;
  }

 private:
  const ParamSet<float>& encoder_params() const { return cfg_.target_encoder ? m_.model->target : m_.model->context; }

  void run_window() {
    const JepaModel<float>& jm = *m_.model;
    const int m = axes_;
    // window[n, a·τ + j] = ring[(head + j) mod τ, n, a]: the oldest frame first.
    for (int j = 0; j < tau_; ++j) {
      const float* f = ring_.data() + static_cast<std::size_t>((head_slot_ + j) % tau_) * N_ * m;
      for (int n = 0; n < N_; ++n)
        for (int a = 0; a < m; ++a)
          window_[(static_cast<std::size_t>(n) * m + a) * tau_ + j] = f[static_cast<std::size_t>(n) * m + a];
    }
    ws_.mark("window");
    const ParamSet<float>& ps = encoder_params();
    jm.tokenizer.forward(ps, window_.data(), 1, tokens_.data(), ws_);
    ws_.mark("tokenizer");
    jm.encoder.forward(ps, {tokens_.data(), 1}, emb_.data(), ws_, EncoderOptions{.register_rows = false});
    // Out in the recording's order: the recording's column column[i] is layout taxel i (without
    // a column map the two orders are one, and the encoder's output is handed out as it is).
    out_.frame = frames_ - 1;
    if (cfg_.column.empty()) {
      out_.embedding = std::span<const float>(emb_.data(), emb_.size());
    } else {
      for (int i = 0; i < N_; ++i)
        std::copy_n(emb_.data() + static_cast<std::size_t>(i) * d_, d_,
                    out_emb_.data() + static_cast<std::size_t>(cfg_.column[static_cast<std::size_t>(i)]) * d_);
      out_.embedding = std::span<const float>(out_emb_.data(), out_emb_.size());
    }
    out_.label = -1;
    if (head_) run_head();
  }

  void run_head() {
    const ProbeHead<float>& h = head_->head;
    const std::vector<float>& shift = head_->info.center_shift;
    const float* x = emb_.data();
    if (!shift.empty()) {
      for (std::size_t k = 0; k < shifted_.size(); ++k) shifted_[k] = emb_[k] + shift[k];
      x = shifted_.data();
    }
    h.probe.forward(h.params, {x, 1, N_}, outputs_.data(), head_ws_);
    ws_.mark("probe");
    const int R = h.regression, C = h.classes;
    for (int r = 0; r < R; ++r) {
      const auto k = static_cast<std::size_t>(r);
      outputs_[k] = static_cast<float>(outputs_[k] * h.scaler.std[k] + h.scaler.mean[k]);
    }
    if (C > 0) {
      float* z = outputs_.data() + R;
      const int best = static_cast<int>(std::max_element(z, z + C) - z);
      const float top = z[best];
      double sum = 0;
      for (int c = 0; c < C; ++c) sum += std::exp(static_cast<double>(z[c] - top));
      for (int c = 0; c < C; ++c) z[c] = static_cast<float>(std::exp(static_cast<double>(z[c] - top)) / sum);
      out_.label = best;
    }
    out_.outputs = std::span<const float>(outputs_.data(), outputs_.size());
  }

  TrainedModel m_;
  std::optional<LoadedProbeHead<float>> head_;
  PipelineConfig cfg_;
  int N_ = 0, d_ = 0, tau_ = 0, axes_ = 0;
  // Buffers, all sized in the constructor.
  std::vector<float> ring_;                // [τ, N, m] the last τ frames, layout order, preprocessed
  AlignedVector<float> window_;            // [N, m·τ] tokenizer rows
  AlignedVector<float> tokens_, emb_;      // [N, d]
  std::vector<float> out_emb_;             // [N, d] in the recording's order (with a column map)
  std::vector<float> shifted_;             // [N, d] embeddings + centring shift
  std::vector<float> outputs_;             // [R + C]
  Workspace<float> ws_, head_ws_;
  PipelineOutput out_;
  int head_slot_ = 0;      // ring slot of the next frame
  int filled_ = 0;         // frames in the ring since restart (up to τ)
  std::int64_t since_ = 0; // complete windows' frames since restart (stride counter)
  std::int64_t frames_ = 0;
};

}  // namespace tjepa
