#pragma once
// The downstream protocol on the simulated grasping hand, end to end (what `tjepa eval` and
// `tjepa demo` run):
//
//   data     one SimulatedHand session (seed data_seed): a contact-free baseline, an unlabelled
//            pre-training recording, a labelled training and a labelled test recording, each of
//            its own episodes; magnetic preprocessing fitted on the baseline and the pre-training
//            recording; optional drift tracking through the session in recording order
//   tasks    object / force / pose (eval/grasp_tasks.hpp; paper, Sec. IV-B) on the labelled
//            recordings
//   rows     constant; ridge on hand-crafted features; the random initial encoder, frozen; the same
//            encoder trained end to end with each head; MAE pre-trained on the same windows with the
//            same budget, frozen; DINO (the teacher) and BYOL (T-DEX's image encoder, the online
//            network) likewise; Tactile-JEPA, frozen (the target encoder). End to end, MAE, DINO
//            and BYOL are the paper's baselines (Sec. IV-C, Table 3)
//   linear   the linear read-outs of each frozen encoder of the main rows (ridge on its pad-mean
//            embeddings and on its token components, score_linear_readouts; one per pre-training
//            seed), beside the ridge row: what the embeddings hold linearly, apart from what the
//            heads learn to find
//   ablation Tactile-JEPA with the masks of the paper's ablation (Sec. V, Table 4): 2L+2G (the
//            default), 4L, 4G, 4 I-JEPA blocks, and 2L+2G with a local (connected) context
//   protocol (paper, Sec. IV-D, evaluation protocol) for each pre-training seed s in `seeds`:
//            pre-train, then `head_seeds` heads per task (head seed s·1000 + h); the table
//            (downstream/score_table.hpp) averages the heads per seed, reports mean ± sd over seeds, and
//            Welch-tests the best two rows
//
// Everything is a function of the config: the same config gives the same table (at the same
// thread count).
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "tjepa/data/drift_tracker.hpp"
#include "tjepa/data/preprocessor.hpp"
#include "tjepa/data/window_source.hpp"
#include "tjepa/eval/grasp_tasks.hpp"
#include "tjepa/eval/pretrain_cache.hpp"
#include "tjepa/graph/skin.hpp"
#include "tjepa/sensors/allegro_xela.hpp"
#include "tjepa/masks/ijepa_blocks.hpp"
#include "tjepa/sim/grasping_hand.hpp"
#include "tjepa/baselines/byol.hpp"
#include "tjepa/train/config.hpp"
#include "tjepa/baselines/dino.hpp"
#include "tjepa/baselines/mae.hpp"
#include "tjepa/train/trained_model.hpp"
#include "tjepa/train/trainer.hpp"

namespace tjepa {

// Tactile-JEPA's pre-training for the grasp protocol: TrainConfig's defaults (2L+2G masks, the
// scaled-down ViT) with the two settings the indenter demo needed for the encoder to move at all
// (docs/evaluation.md, "Why the protocol is set this way"), fixed before any grasp run: drift tracking (the sensor drifts during a
// session) and AdamW's beta2 at 0.99.
inline TrainConfig grasp_pretrain_config() {
  TrainConfig c;
  c.data.drift_time_constant = 200;
  c.adamw.beta2 = 0.99;
  return c;
}

struct GraspEvalConfig {
  std::uint64_t data_seed = 0;
  std::vector<std::uint64_t> seeds{0, 1, 2};  // pre-training seeds
  int head_seeds = 3;                         // heads per task and pre-training seed
  // Frames of each recording (100 Hz; an episode is about 5 s): 200 000 unlabelled (about 380
  // episodes); 300 000 labelled for training, about 36 episodes per object, so that which episodes
  // a head validates on does not decide what it learns (the tasks still take at most 1500 windows
  // or 300 sequences, spread over the recording); 100 000 held out, about 12 episodes per object.
  int baseline_frames = 300, pretrain_frames = 200000, train_frames = 300000, test_frames = 100000;
  GraspSimConfig sim;
  TrainConfig train = grasp_pretrain_config();  // Tactile-JEPA (and MAE's budget: steps, batch, schedule)
  double mae_mask_ratio = 0.75;
  // BYOL's sizes (T-DEX's by default): image side (AlexNet needs >= 63), AlexNet's widths, the
  // projection and the MLPs' hidden width.
  int byol_image_size = 224;
  std::array<int, 5> byol_widths = AlexNetConfig{}.widths;
  int byol_projection = 1024, byol_hidden = 4096;
  GraspTaskConfig tasks{.max_object_windows = 1500, .max_force_windows = 1500, .max_pose_sequences = 300};
  GraspHeadConfig heads;
  // Rows to run.
  bool ridge = true, random = true, end_to_end = true, mae = true, dino = true, byol = true, jepa = true,
       ablation = true;
  bool linear_readout = true;  // the linear read-out table of the frozen main rows
  int readout_components = 3;  // k of its token components (as many numbers per taxel as its 3 axes)
  // Directory of pre-trained encoders kept between runs (eval/pretrain_cache.hpp; empty: none):
  // a row and seed found there is read instead of pre-trained, with the same weights. It changes
  // no result, so to_json leaves it out.
  std::string pretrain_cache;

  void validate() const {
    require<ConfigError>(!seeds.empty() && head_seeds > 0, "GraspEvalConfig: ", seeds.size(), " seeds, ", head_seeds,
                         " head seeds, expected at least one of each");
    require<ConfigError>(baseline_frames > 0 && pretrain_frames > 0 && train_frames > 0 && test_frames > 0,
                         "GraspEvalConfig: frame counts must be > 0");
    require<ConfigError>(jepa || !ablation, "GraspEvalConfig: the mask ablation needs the Tactile-JEPA row (its 2L+2G "
                         "row); run with jepa or without the ablation");
    require<ConfigError>(!byol || byol_image_size >= 63, "GraspEvalConfig: byol_image_size = ", byol_image_size,
                         ", expected >= 63 (AlexNet's smallest input)");
    sim.validate();
    train.validate();
    tasks.validate();
    require<ConfigError>(readout_components > 0 && readout_components <= train.model.dim, "GraspEvalConfig: readout_components = ",
                         readout_components, ", expected in [1, dim = ", train.model.dim, "]");
    // The tasks carry episodes: validation by episodes excludes blocks (validation_split).
    for (const HeadTrainConfig* h : {&heads.probe, &heads.sequence})
      require<ConfigError>(!h->validation_groups || h->validation_blocks == 0, "GraspEvalConfig: heads validate by ",
                           "episodes (validation_groups) and by ", h->validation_blocks,
                           " blocks at once; set validation_blocks = 0 or validation_groups = false");
    const int overlap = (tasks.sequence_length + tasks.sequence_stride - 1) / tasks.sequence_stride - 1;
    require<ConfigError>(heads.sequence.validation_blocks == 0 || heads.sequence.validation_gap >= overlap,
                         "GraspEvalConfig: heads.sequence.validation_gap = ", heads.sequence.validation_gap,
                         ", expected >= ", overlap, " (pose sequences of ", tasks.sequence_length, " windows starting ",
                         tasks.sequence_stride, " apart overlap up to ", overlap, " starts away)");
    require<ConfigError>(tasks.label_pad == sim.label_pad, "GraspEvalConfig: tasks.label_pad = ", tasks.label_pad,
                         ", sim.label_pad = ", sim.label_pad, ", expected equal");
  }

  nlohmann::json to_json() const {
    return {{"data_seed", data_seed},
            {"seeds", seeds},
            {"head_seeds", head_seeds},
            {"frames", {{"baseline", baseline_frames}, {"pretrain", pretrain_frames}, {"train", train_frames},
                        {"test", test_frames}}},
            {"train", train.to_json()},
            {"mae_mask_ratio", mae_mask_ratio},
            {"byol", {{"image_size", byol_image_size}, {"widths", byol_widths}, {"projection", byol_projection},
                      {"hidden", byol_hidden}}},
            {"tasks", {{"label_pad", tasks.label_pad}, {"sequence_length", tasks.sequence_length},
                       {"sequence_stride", tasks.sequence_stride}, {"max_object_windows", tasks.max_object_windows},
                       {"max_force_windows", tasks.max_force_windows}, {"max_pose_sequences", tasks.max_pose_sequences}}},
            {"heads", {{"probe_heads", heads.probe_heads}, {"max_epochs", heads.probe.max_epochs},
                       {"patience", heads.probe.patience}, {"probe_batch", heads.probe.batch}, {"lr", heads.probe.lr},
                       {"object_stop_on_error", heads.probe.stop_on_error},
                       {"sequence_patience", heads.sequence.patience},
                       {"sequence_validation_blocks", heads.sequence.validation_blocks},
                       {"sequence_validation_gap", heads.sequence.validation_gap},
                       {"validation_by_episode", heads.probe.validation_groups && heads.sequence.validation_groups},
                       {"sequence_batch", heads.sequence.batch}, {"sequence_max_epochs", heads.sequence.max_epochs},
                       {"end_to_end_max_epochs", heads.end_to_end_max_epochs},
                       {"end_to_end_patience", heads.end_to_end_patience},
                       {"standardize_features", heads.standardize_features},
                       {"probe_pooling", to_string(heads.probe_pooling.kind)},
                       {"sequence_pooling", to_string(heads.sequence_pooling.kind)},
                       {"pooling_components", heads.sequence_pooling.components}}},
            {"rows", {{"ridge", ridge}, {"random", random}, {"end_to_end", end_to_end}, {"mae", mae}, {"dino", dino}, {"byol", byol}, {"jepa", jepa}, {"ablation", ablation}, {"linear_readout", linear_readout}, {"readout_components", readout_components}}}};
  }
};

// The simulated session and its tasks.
struct GraspEvalData {
  Skin skin;
  Preprocessor pre;
  std::optional<DriftTracker> drift;
  std::optional<WindowSource> pretrain, train, test;
  GraspTasks train_tasks, test_tasks;
  std::array<double, 3> contact_share{};  // share of frames with any contact per recording
};

// The DriftTracker of a run (none when run.drift_time_constant is 0), fitted on the no-contact
// baseline, then run over recs in order: one continuous session of one sensor.
inline std::optional<DriftTracker> track_drift(const TrainConfig& run, const Recording& baseline,
                                               std::span<Recording* const> recs) {
  if (run.data.drift_time_constant <= 0) return std::nullopt;
  DriftTrackerConfig c = DriftTrackerConfig::magnetic();
  c.time_constant = run.data.drift_time_constant;
  DriftTracker tracker(c);
  tracker.fit(baseline);
  for (Recording* r : recs) tracker.apply(*r);
  return tracker;
}

inline GraspEvalData simulate_grasp_eval_data(const GraspEvalConfig& c) {
  c.validate();
  GraspEvalData d{layouts::allegro_xela(), Preprocessor(PreprocessConfig::xela_counts()), {}, {}, {}, {}, {}, {}, {}};
  SimulatedHand sim(d.skin.layout, c.sim, c.data_seed);
  Recording baseline = sim.record_baseline(c.baseline_frames);
  GraspRecording pre = sim.record(c.pretrain_frames);
  // The labelled recordings start new episodes (reseed keeps the sensor and its drift), so no
  // episode runs from one recording into the next.
  sim.reseed(c.data_seed ^ 0x747261696e5f6570ull);  // "train_ep"
  GraspRecording tr = sim.record(c.train_frames);
  sim.reseed(c.data_seed ^ 0x746573745f657073ull);  // "test_eps"
  GraspRecording te = sim.record(c.test_frames);
  d.drift = track_drift(c.train, baseline,
                        std::array<Recording*, 3>{&pre.recording, &tr.recording, &te.recording});
  d.pre.fit_baseline(baseline);
  d.pre.fit(pre.recording);
  const GraspRecording* recs[3] = {&pre, &tr, &te};
  for (int r = 0; r < 3; ++r) {
    std::size_t touched = 0;
    for (const GraspLabel& l : recs[r]->labels) touched += l.contact_mask != 0;
    d.contact_share[static_cast<std::size_t>(r)] = static_cast<double>(touched) / static_cast<double>(recs[r]->labels.size());
  }
  const WindowSpec spec{c.train.data.tau};
  d.pretrain.emplace(std::move(pre.recording), spec, std::vector<FrameLabel>{}, d.pre);
  d.train.emplace(std::move(tr.recording), spec, std::vector<FrameLabel>{}, d.pre);
  d.test.emplace(std::move(te.recording), spec, std::vector<FrameLabel>{}, d.pre);
  d.train_tasks = grasp_tasks(*d.train, tr.labels, c.tasks);
  d.test_tasks = grasp_tasks(*d.test, te.labels, c.tasks);
  return d;
}

// A mask variant of the ablation: its name and masks (the rest of the run is the main row's).
// A variant's masks are part of its TrainConfig, so the pre-training cache keys them.
struct MaskVariant {
  std::string name;
  MaskConfig masks;
};

inline std::vector<MaskVariant> grasp_mask_ablation(const TrainConfig& c) {
  const MaskConfig base = c.masks;
  std::vector<MaskVariant> v;
  auto with = [&](std::string name, int local, int global) {
    MaskVariant m{std::move(name), base};
    m.masks.num_local = local;
    m.masks.num_global = global;
    return m;
  };
  v.push_back(with("4L", 4, 0));
  v.push_back(with("4G", 0, 4));
  MaskVariant blocks{"4 I-JEPA blocks", base};
  blocks.masks.scheme = TargetScheme::ijepa_blocks;
  blocks.masks.blocks.num_targets = 4;
  v.push_back(blocks);
  MaskVariant local = with("2L+2G, local context", 2, 2);
  local.masks.context_sampling = ContextSampling::local;
  v.push_back(local);
  return v;
}

struct GraspEvalResult {
  // linear: the linear read-outs of the main rows' frozen encoders; ablation_linear: of the
  // ablation's encoders (both with linear_readout).
  ScoreTable main = grasp_score_table("Simulated grasping hand: frozen encoders, baselines, end to end");
  ScoreTable ablation = grasp_score_table("Mask ablation (Tactile-JEPA, frozen)");
  ScoreTable linear =
      grasp_score_table("Linear read-outs of the frozen encoders (ridge on pad-mean embeddings, on token components)");
  ScoreTable ablation_linear = grasp_score_table("Mask ablation: linear read-outs (Tactile-JEPA, frozen)");
  nlohmann::json info;  // config, data sizes, timings, pre-training losses
};

// A row of the protocol (or a group of rows that share one model): whether the config asks for it,
// and what it does for one pre-training seed, from its own setup to its recorded scores.
struct GraspEvalRow {
  bool on = false;
  std::function<void(std::uint64_t seed)> run;
};

// Runs the protocol: the main rows seed by seed, then the ablation seed by seed. progress(line)
// reports each stage; after_seed(result so far) runs after each seed of each (e.g. to write
// partial tables).
inline GraspEvalResult run_grasp_eval(const GraspEvalConfig& c, const std::function<void(const std::string&)>& progress = {},
                                      const std::function<void(const GraspEvalResult&)>& after_seed = {}) {
  using clock = std::chrono::steady_clock;
  const auto t0 = clock::now();
  auto say = [&](const std::string& s) {
    if (progress) progress(s);
  };
  auto seconds = [](clock::time_point a) { return std::chrono::duration<double>(clock::now() - a).count(); };
  say("simulating the grasping hand: " + std::to_string(c.pretrain_frames) + " unlabelled + " +
      std::to_string(c.train_frames) + " labelled + " + std::to_string(c.test_frames) + " held-out frames at 100 Hz");
  const GraspEvalData d = simulate_grasp_eval_data(c);
  const GraspTasks &tr = d.train_tasks, &te = d.test_tasks;
  say("tasks (train / test): object " + std::to_string(tr.object.size()) + " / " + std::to_string(te.object.size()) +
      " windows, force " + std::to_string(tr.force.size()) + " / " + std::to_string(te.force.size()) +
      " windows, pose " + std::to_string(tr.pose.size()) + " / " + std::to_string(te.pose.size()) + " sequences of " +
      std::to_string(tr.pose.length) + " windows; " + std::to_string(d.pretrain->size()) + " pre-training windows");
  GraspEvalResult res;
  res.info = {{"config", c.to_json()},
              {"data", {{"pretrain_windows", d.pretrain->size()},
                        {"contact_share", d.contact_share},
                        {"train", {{"object", tr.object.size()}, {"force", tr.force.size()}, {"pose_sequences", tr.pose.size()}}},
                        {"test", {{"object", te.object.size()}, {"force", te.force.size()}, {"pose_sequences", te.pose.size()}}}}},
              {"simulate_seconds", seconds(t0)},
              {"pretraining", nlohmann::json::array()}};
  const int axes = d.pretrain->axes();
  const TaxelGraph& graph = d.skin.graph;
  const GraspHeadConfig& hc = c.heads;

  // The run's config at pre-training seed s: every row starts from it.
  auto seeded = [&](std::uint64_t s) {
    TrainConfig cfg = c.train;
    cfg.seed = s;
    return cfg;
  };
  // A baseline's encoder given the graph positions make_jepa_model gives Tactile-JEPA's: every
  // method starts from the same encoder.
  auto same_start = [&](auto& model, const TrainConfig& cfg, std::uint64_t s) {
    if (cfg.model.position_eigenvectors > 0)
      model.set_positions(graph_positions(graph, cfg.model.dim, cfg.model.position_eigenvectors, cfg.model.position_scale, s));
  };
  auto seeds_of = [&](std::uint64_t s) {
    std::vector<std::uint64_t> h;
    for (int i = 0; i < c.head_seeds; ++i) h.push_back(s * 1000 + static_cast<std::uint64_t>(i));
    return h;
  };
  auto stage = [&](const std::string& what) {
    return [&, what](const std::string& s) { say("  " + what + ": " + s); };
  };
  PretrainCache cache;
  if (!c.pretrain_cache.empty()) {
    // The pre-training windows come from the baseline and the unlabelled recording (drift
    // tracking and the preprocessor are fitted on those two): the labelled ones are not in the key.
    const auto t = clock::now();
    cache = PretrainCache(c.pretrain_cache, {{"data_seed", c.data_seed},
                                             {"baseline_frames", c.baseline_frames},
                                             {"pretrain_frames", c.pretrain_frames},
                                             {"pretrain_windows", d.pretrain->size()},
                                             {"fingerprint", fingerprint(*d.pretrain)}});
    res.info["pretrain_cache"] = c.pretrain_cache;
    say("pre-training cache " + c.pretrain_cache + " (data fingerprint in " + std::to_string(seconds(t)) + " s)");
  }
  // The pre-trained encoder of row `name` at seed s read from the cache into params and its log
  // entry recorded; false when the cache does not hold it.
  auto from_cache = [&](const std::string& name, std::uint64_t s, const nlohmann::json& key, ParamSet<float>& params) {
    std::optional<nlohmann::json> entry = cache.load(key, params);
    if (!entry) return false;
    (*entry)["cached"] = cache.path(key).string();
    res.info["pretraining"].push_back(*entry);
    say("  " + name + " seed " + std::to_string(s) + ": pre-trained encoder read from " + cache.path(key).string());
    return true;
  };
  // A finished pre-training: its log entry recorded, its encoder written to the cache.
  auto pretrained = [&](const nlohmann::json& key, ParamSet<float>& params, const nlohmann::json& entry) {
    res.info["pretraining"].push_back(entry);
    cache.save(key, params, entry);
  };
  // Pre-trains a Tactile-JEPA model with collator masks (or reads its target encoder from the
  // cache); logs its loss curve's ends and time.
  auto pretrain_jepa = [&](const std::string& name, std::uint64_t s, const MaskVariant* v) {
    TrainConfig cfg = seeded(s);
    if (v) cfg.masks = v->masks;
    auto model = make_jepa_model<float>(cfg, graph, axes, s);
    const nlohmann::json key = cache.key(name, s, {{"train", cfg.to_json()}});
    if (from_cache(name, s, key, model->target)) return model;
    std::optional<GridPlacement> grid;  // I-JEPA blocks draw on the layout's grid placement
    if (cfg.masks.scheme == TargetScheme::ijepa_blocks)
      grid = GridPlacement::from_layout(d.skin.layout, layouts::allegro::kPhalanxPitch);
    JepaTrainer<float> trainer(*model, *d.pretrain, graph, cfg, JepaLoss<float>{}, std::move(grid));
    const auto t = clock::now();
    JepaStepStats first, last;
    trainer.on_step = [&](const JepaStepStats& st) {
      if (st.step == 0) first = st;
      last = st;
      if ((st.step + 1) % std::max<std::int64_t>(1, cfg.schedule.steps / 10) == 0)
        say("  " + name + " seed " + std::to_string(s) + ": step " + std::to_string(st.step + 1) + "/" +
            std::to_string(cfg.schedule.steps) + ", loss " + std::to_string(st.loss) + ", target std over samples " +
            std::to_string(st.target_sample_std));
    };
    trainer.run();
    pretrained(key, model->target,
               {{"row", name}, {"seed", s}, {"first_loss", first.loss}, {"last_loss", last.loss},
                {"first_target_sample_std", first.target_sample_std},
                {"last_target_sample_std", last.target_sample_std}, {"seconds", seconds(t)}});
    return model;
  };

  // A baseline's pre-training (or its encoder `keep` read from the cache): the Trainer that
  // make() builds runs, a progress line every tenth of the run (detail(st) adds to it), its log
  // entry is recorded and `keep` cached.
  auto pretrain_baseline = [&](const std::string& name, std::uint64_t s, std::int64_t steps, const nlohmann::json& key,
                               ParamSet<float>& keep, auto&& make, auto&& detail) {
    if (from_cache(name, s, key, keep)) return;
    const auto t = clock::now();
    auto trainer = make();
    trainer.on_step = [&](const auto& st) {
      if ((st.step + 1) % std::max<std::int64_t>(1, steps / 10) == 0)
        say("  " + name + " seed " + std::to_string(s) + ": step " + std::to_string(st.step + 1) + "/" +
            std::to_string(steps) + ", loss " + std::to_string(st.loss) + detail(st));
    };
    const auto log = trainer.run();
    pretrained(key, keep,
               {{"row", name}, {"seed", s}, {"first_loss", log.front().loss}, {"last_loss", log.back().loss},
                {"seconds", seconds(t)}});
  };
  auto no_detail = [](const auto&) { return std::string(); };

  {  // the baselines without an encoder
    const auto t = clock::now();
    const GraspScores k = score_constant(tr, te);
    res.main.row("constant").runs.assign(c.seeds.size(), {std::vector<double>(k.begin(), k.end())});
    say("constant: done");
    if (c.ridge) {
      ScoreRow& r = res.main.row("ridge (pad sums + taxel means)");
      for (std::uint64_t s : c.seeds)
        r.add_sample(std::vector<GraspScores>{score_ridge(*d.train, tr, *d.test, te, d.skin.layout.group, d.skin.layout.num_groups(), s)});
      say("ridge: done (" + std::to_string(seconds(t)) + " s)");
      if (c.linear_readout) res.linear.row(r.name) = r;
    }
  }
  // A frozen encoder's scores recorded: its heads in `heads` under name, its linear read-outs (if
  // any) in `linear` under "<linear_name>: pad means" and ": token components".
  auto record = [&](const FrozenEncoderScores& f, ScoreTable& heads, ScoreTable& linear, const std::string& name,
                    const std::string& linear_name) {
    heads.row(name).add_sample(f.heads);
    if (f.linear) {
      linear.row(linear_name + ": pad means").add_sample(std::vector<GraspScores>{f.linear->group_means});
      linear.row(linear_name + ": token components").add_sample(std::vector<GraspScores>{f.linear->token_components});
    }
  };
  // A frozen encoder scored (heads, and the linear read-outs with linear_readout) and recorded.
  auto frozen_row = [&](ScoreTable& heads, ScoreTable& linear, const std::string& name, const std::string& linear_name,
                        std::uint64_t s, const ParamSet<float>& params, const Tokenizer& tokenizer,
                        const Encoder& encoder) {
    std::optional<LinearReadoutConfig> readout;
    if (c.linear_readout)
      readout = LinearReadoutConfig{d.skin.layout.group, d.skin.layout.num_groups(), c.readout_components, s};
    FrozenEncoderScores f = score_frozen_encoder(params, tokenizer, encoder, *d.train, tr, *d.test, te, hc,
                                                 seeds_of(s), stage(name), readout);
    record(f, heads, linear, name, linear_name);
    return f;
  };

  // The rows with an encoder, in the table's order; each pre-training seed runs them all.
  const std::vector<GraspEvalRow> rows = {
      {c.random || c.end_to_end,  // the random initial encoder, frozen, and the same encoder trained end to end
       [&](std::uint64_t s) {
         const TrainConfig cfg = seeded(s);
         auto model = make_jepa_model<float>(cfg, graph, axes, s);
         if (c.random)
           frozen_row(res.main, res.linear, "random init, frozen", "random init", s, model->target, model->tokenizer,
                      model->encoder);
         if (c.end_to_end)
           res.main.row(end_to_end_name(hc))
               .add_sample(score_end_to_end(model->context, model->tokenizer, model->encoder, *d.train, tr, *d.test, te,
                                            hc, seeds_of(s), stage("end to end")));
       }},
      {c.mae,
       [&](std::uint64_t s) {
         const TrainConfig cfg = seeded(s);
         MaeModel<float> mae(mae_config(cfg, graph.num_nodes(), axes, c.mae_mask_ratio), s);
         same_start(mae, cfg, s);
         const nlohmann::json key = cache.key("MAE", s, {{"train", cfg.to_json()}, {"mae_mask_ratio", c.mae_mask_ratio}});
         pretrain_baseline("MAE", s, cfg.schedule.steps, key, mae.context,
                           [&] { return MaeTrainer<float>(mae, *d.pretrain, cfg); }, no_detail);
         frozen_row(res.main, res.linear, "MAE, frozen", "MAE", s, mae.context, mae.tokenizer, mae.encoder);
       }},
      {c.dino,  // the teacher encoder, as DINO evaluates (its register row left out of the features)
       [&](std::uint64_t s) {
         const TrainConfig cfg = seeded(s);
         DinoModel<float> dino(dino_config(cfg, graph.num_nodes(), axes), s);
         same_start(dino, cfg, s);
         const nlohmann::json key = cache.key("DINO", s, {{"train", cfg.to_json()}});
         pretrain_baseline("DINO", s, cfg.schedule.steps, key, dino.teacher,
                           [&] { return DinoTrainer<float>(dino, *d.pretrain, cfg); },
                           [](const DinoStepStats& st) {
                             return " (dino " + std::to_string(st.dino) + ", ibot " + std::to_string(st.ibot) +
                                    ", koleo " + std::to_string(st.koleo) + ")";
                           });
         frozen_row(res.main, res.linear, "DINO, frozen", "DINO", s, dino.teacher, dino.tokenizer, dino.encoder);
       }},
      {c.byol,  // the online encoder, as T-DEX evaluates; its features one token per cell of the pooled map
       [&](std::uint64_t s) {
         const TrainConfig cfg = seeded(s);
         ByolConfig bc = byol_config(cfg, axes);
         bc.encoder.image_size = bc.image.image_size = c.byol_image_size;
         bc.encoder.widths = c.byol_widths;
         bc.projection = c.byol_projection, bc.hidden = c.byol_hidden;
         ByolModel<float> byol(bc, s);
         const TaxelCanvas canvas = TaxelCanvas::from_layout(d.skin.layout);
         const nlohmann::json key = cache.key("BYOL", s, {{"train", cfg.to_json()}, {"byol", byol.config.to_json()}});
         pretrain_baseline("BYOL", s, cfg.schedule.steps, key, byol.online,
                           [&] { return ByolTrainer<float>(byol, *d.pretrain, canvas, cfg); }, no_detail);
         const int cells = byol.config.encoder.pooled * byol.config.encoder.pooled, C = byol.config.encoder.widths[4];
         AlignedVector<float> etr = byol_embed(byol, byol.online, canvas, *d.train, tr.windows);
         AlignedVector<float> ete = byol_embed(byol, byol.online, canvas, *d.test, te.windows);
         GraspHeadConfig bh = hc;  // attention heads that split its C channels: at most the protocol's
         while (C % bh.probe_heads != 0) --bh.probe_heads;
         record(score_frozen_embeddings(std::move(etr), std::move(ete), cells, C, tr, te, bh, seeds_of(s),
                                        stage("BYOL, frozen")),
                res.main, res.linear, "BYOL, frozen (random-init AlexNet)", "BYOL");
       }},
      {c.jepa,  // the target encoder; also the ablation's default row
       [&](std::uint64_t s) {
         auto model = pretrain_jepa("Tactile-JEPA", s, nullptr);
         const FrozenEncoderScores f = frozen_row(res.main, res.linear, "Tactile-JEPA, frozen", "Tactile-JEPA", s,
                                                  model->target, model->tokenizer, model->encoder);
         if (c.ablation) record(f, res.ablation, res.ablation_linear, "2L+2G (default)", "2L+2G (default)");
       }},
  };
  for (std::uint64_t s : c.seeds) {
    say("pre-training seed " + std::to_string(s));
    for (const GraspEvalRow& r : rows)
      if (r.on) r.run(s);
    res.info["total_seconds"] = seconds(t0);
    if (after_seed) after_seed(res);
  }
  // The ablation after the main table, so that the main table is complete first.
  if (c.ablation)
    for (std::uint64_t s : c.seeds) {
      say("mask ablation, seed " + std::to_string(s));
      for (const MaskVariant& v : grasp_mask_ablation(c.train)) {
        auto model = pretrain_jepa(v.name, s, &v);
        frozen_row(res.ablation, res.ablation_linear, v.name, v.name, s, model->target, model->tokenizer,
                   model->encoder);
      }
      res.info["total_seconds"] = seconds(t0);
      if (after_seed) after_seed(res);
    }
  res.info["total_seconds"] = seconds(t0);
  return res;
}

}  // namespace tjepa
