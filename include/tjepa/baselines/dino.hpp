#pragma once
// DINO, the Sparsh-skin baseline of the paper's Table 3, as the Tactile-JEPA reference code runs
// it on a skin (XelaDINOv2Module: DINOv2's class-token loss, iBOT's masked-token loss, KoLeo):
// a student encoder with a DINO head learns to predict the prototype distribution of an EMA
// teacher from smaller and masked views of the same window.
//
// Legend: B samples, N tokens, d the encoder's width, P prototypes, Kg / Kl tokens per global /
// local view, V = G + L views (G global, L local).
//
//   tokens      = tokenizer(θ, x)                       [B, N, d] once; every view gathers from it
//   views       = G global runs of Kg tokens, L local runs of Kl tokens, Kg = ⌊N·U(global_scale)⌋,
//                 Kl = ⌊N·U(local_scale)⌋ drawn once per step, each run starting at a uniform
//                 token of each sample (contiguous in the taxel order, as the reference's views)
//   ibot        = per global view and sample, ⌊Kg·U(ibot_ratio)⌋ of its tokens, at random
//   student     = encoder(θ, view; ibot → mask token)   [·, 1 + K, d]: row 0 the class token
//   teacher     = encoder(ξ, global views)              [G·B, 1 + Kg, d]
//   s, t        = head(·) of the class tokens and of the iBOT-masked tokens
//   L_dino      = Σ_{(i, j), i ≠ j} mean_b ℓ(sᵢ, softmax((tⱼ − c) / τₜ)) / #pairs
//                 (i over the V student views, j over the G teacher views)
//   L_ibot      = mean over masked tokens of ℓ(s, softmax((t − c_p) / τₜ)) / G
//   L_koleo     = koleo_weight · Σ over global views of KoLeo(student class tokens)
//   L           = L_dino + L_ibot + L_koleo
//   update      = clip, AdamW on (encoder, head); ξ ← m ξ + (1 − m) θ; centers moved toward
//                 this step's teacher means (used from the next step); τₜ linear from
//                 teacher_temp[0] to [1] over the first teacher_warmup of the run
// ℓ is dino_cross_entropy (baselines/dino_loss.hpp) at student temperature τₛ.
//
// Differences from the reference, on purpose: the views need no taxel coordinates on the input
// (the encoder's position table says where a token is, as for MAE here, so the encoder is
// Tactile-JEPA's plus one register row and a mask token); the teacher head starts as a copy of
// the student's (DINO's rule; the reference draws it anew); the head's sizes follow the run's
// width (dino_config) rather than the reference's 2048 / 256 / 65536.
//
// Parameter names: the student's encoder under "context_encoder." (JepaModel::context's names
// plus register_tokens and mask_token), its head under "dino_head." (baselines/dino_head.hpp); the
// teacher's under "target_encoder." and "target_head."; the two centers under "dino_center."
// (center, patch_center [P], no gradient). A checkpoint holds them all, so a resumed run
// continues bit for bit.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "tjepa/core/error.hpp"
#include "tjepa/core/random.hpp"
#include "tjepa/baselines/dino_head.hpp"
#include "tjepa/optim/adamw.hpp"
#include "tjepa/optim/ema.hpp"
#include "tjepa/optim/schedule.hpp"
#include "tjepa/train/config.hpp"
#include "tjepa/baselines/dino_loss.hpp"
#include "tjepa/train/jepa_model.hpp"
#include "tjepa/train/objective.hpp"
#include "tjepa/train/trainer.hpp"

namespace tjepa {

struct DinoConfig : ContextEncoderConfig {
  DinoHeadConfig head;                  // in_dim = encoder.dim
  int global_views = 2, local_views = 8;
  std::array<double, 2> global_scale{0.4, 1.0};  // share of the N tokens a global view keeps
  std::array<double, 2> local_scale{0.1, 0.4};
  std::array<double, 2> ibot_ratio{0.1, 0.5};    // share of a global view's tokens masked in the student
  double student_temp = 0.1;
  std::array<double, 2> teacher_temp{0.04, 0.07};
  double teacher_warmup = 0.02;  // share of the run over which τₜ rises (the reference: 10 of 500 epochs)
  double center_momentum = 0.9;
  double koleo_weight = 0.1;
  double drop_path = 0.0;        // in the student's blocks (the reference: 0.3)
  double clip_grad_norm = 10.0;

  static DinoConfig reference(int num_tokens, int in_dim, int axes = 1) {
    DinoConfig c = reference_for<DinoConfig>(num_tokens, in_dim, axes);
    c.encoder.register_tokens = 1;
    c.encoder.mask_token = true;
    c.drop_path = 0.3;
    return c;
  }

  // Tokens of a view of scale u: ⌊N·u⌋, at least 1 (2 for a global view's KoLeo and masking).
  static int view_tokens(int N, double u, int at_least) { return std::clamp(static_cast<int>(N * u), at_least, N); }

  void validate() const {
    validate_encoder("DinoConfig");
    require<ConfigError>(encoder.register_tokens >= 1 && encoder.mask_token, "DinoConfig: the encoder has ",
                         encoder.register_tokens, " register rows and ", encoder.mask_token ? "a" : "no",
                         " mask token, expected at least 1 (the class token) and a mask token");
    require<ConfigError>(head.in_dim == encoder.dim, "DinoConfig: head.in_dim = ", head.in_dim, ", expected encoder.dim = ",
                         encoder.dim);
    head.validate();
    require<ConfigError>(global_views >= 1 && local_views >= 0, "DinoConfig: ", global_views, " global and ",
                         local_views, " local views, expected >= 1 and >= 0");
    auto range = [](const std::array<double, 2>& r, const char* key) {
      require<ConfigError>(r[0] > 0 && r[0] <= r[1] && r[1] <= 1, "DinoConfig: ", key, " = [", r[0], ", ", r[1],
                           "], expected 0 < lo <= hi <= 1");
    };
    range(global_scale, "global_scale");
    range(local_scale, "local_scale");
    range(ibot_ratio, "ibot_ratio");
    require<ConfigError>(student_temp > 0 && teacher_temp[0] > 0 && teacher_temp[1] > 0, "DinoConfig: temperatures ",
                         student_temp, ", [", teacher_temp[0], ", ", teacher_temp[1], "], expected > 0");
    require<ConfigError>(teacher_warmup >= 0 && teacher_warmup <= 1, "DinoConfig: teacher_warmup = ", teacher_warmup,
                         ", expected a share of the run in [0, 1]");
    require<ConfigError>(center_momentum >= 0 && center_momentum < 1, "DinoConfig: center_momentum = ",
                         center_momentum, ", expected in [0, 1)");
    require<ConfigError>(koleo_weight >= 0, "DinoConfig: koleo_weight = ", koleo_weight, ", expected >= 0");
    require<ConfigError>(drop_path >= 0 && drop_path < 1, "DinoConfig: drop_path = ", drop_path, ", expected in [0, 1)");
    require<ConfigError>(clip_grad_norm > 0, "DinoConfig: clip_grad_norm = ", clip_grad_norm, ", expected > 0");
  }

  nlohmann::json to_json() const {
    nlohmann::json j = encoder_json();
    j["register_tokens"] = encoder.register_tokens;
    j["head"] = {{"hidden", head.hidden}, {"bottleneck", head.bottleneck}, {"prototypes", head.prototypes}};
    j["views"] = {global_views, local_views};
    j["global_scale"] = global_scale, j["local_scale"] = local_scale, j["ibot_ratio"] = ibot_ratio;
    j["student_temp"] = student_temp, j["teacher_temp"] = teacher_temp, j["teacher_warmup"] = teacher_warmup;
    j["center_momentum"] = center_momentum, j["koleo_weight"] = koleo_weight;
    j["drop_path"] = drop_path, j["clip_grad_norm"] = clip_grad_norm;
    return j;
  }
};

// The DINO config of a Tactile-JEPA run's encoder: the same tokenizer and encoder as
// cfg.model_config(num_tokens, axes) plus a class row and a mask token; a head of hidden 4d, bottleneck
// d and 16d prototypes (the reference: 2048, 256, 65536 at d = 192).
inline DinoConfig dino_config(const TrainConfig& cfg, int num_tokens, int axes) {
  const JepaConfig j = cfg.model_config(num_tokens, axes);
  DinoConfig c = DinoConfig::reference(num_tokens, j.in_dim, axes);
  static_cast<ContextEncoderConfig&>(c) = static_cast<const ContextEncoderConfig&>(j);
  c.encoder.register_tokens = 1;
  c.encoder.mask_token = true;
  c.head = DinoHeadConfig{j.encoder.dim, 4 * j.encoder.dim, j.encoder.dim, 16 * j.encoder.dim};
  c.drop_path = cfg.step.drop_path;
  c.clip_grad_norm = cfg.step.clip_grad_norm;
  return c;
}

template <class T>
class DinoModel {
 public:
  DinoConfig config;
  ParamSet<T> student, student_head, teacher, teacher_head, centers;
  Tokenizer tokenizer;
  Encoder encoder;
  DinoHead head;
  ParamId center, patch_center;

  // The student's encoder starts as JepaModel(c, seed).context for the same encoder config and
  // seed would (plus its register and mask rows); the teacher as a copy of the student.
  DinoModel(const DinoConfig& c, std::uint64_t seed) : config(c) {
    c.validate();
    add_context_encoder(student, c, tokenizer, encoder);
    head = DinoHead(student_head, c.head);
    center = centers.add("center", {c.head.prototypes}, ParamInit::zeros);
    patch_center = centers.add("patch_center", {c.head.prototypes}, ParamInit::zeros);
    student.allocate();
    student_head.allocate();
    centers.allocate();
    init_context_encoder(student, tokenizer, c, seed);
    init_params(student_head, seed ^ 0x64696e6f68656164ull);  // "dinohead": an unrelated stream
    teacher = student;
    teacher_head = student_head;
  }

  // Overwrites the student's and the teacher's position table with rows [N, d] (row-major), as
  // JepaModel::set_positions. Init only.
  void set_positions(std::span<const double> rows) {
    detail::check_position_rows(rows, num_tokens(), dim(), "DinoModel::set_positions");
    for (ParamSet<T>* ps : {&student, &teacher}) std::copy(rows.begin(), rows.end(), ps->value(encoder.pos_embed()));
  }

  int num_tokens() const { return config.encoder.num_tokens; }
  int dim() const { return config.encoder.dim; }
  int token_width() const { return tokenizer.width; }

  // What AdamW and gradient clipping see.
  std::vector<PrefixedParams<T>> trainable() { return {{"context_encoder.", &student}, {"dino_head.", &student_head}}; }
  // What a checkpoint holds.
  std::vector<PrefixedParams<T>> parts() {
    return {{"context_encoder.", &student},
            {"dino_head.", &student_head},
            {"target_encoder.", &teacher},
            {"target_head.", &teacher_head},
            {"dino_center.", &centers}};
  }
};

// The views, masks and terms of one DINO step (what a test or a log may read).
struct DinoViews {
  int B = 0, Kg = 0, Kl = 0;
  std::vector<int> global, local;         // [G·B, Kg], [L·B, Kl] token ids, view-major
  std::vector<std::uint8_t> ibot;         // [G·B, Kg] nonzero: masked in the student
  std::vector<int> ibot_rows;             // the masked positions, as rows of [G·B, Kg]
};

// Draws step s's views of B samples from `seed` (the same seed and step give the same views).
inline DinoViews sample_dino_views(const DinoConfig& c, int B, std::uint64_t seed, std::uint64_t s) {
  const int N = c.encoder.num_tokens, G = c.global_views, L = c.local_views;
  Rng r(seed, s);
  DinoViews v;
  v.B = B;
  v.Kg = DinoConfig::view_tokens(N, r.uniform(c.global_scale[0], c.global_scale[1]), std::min(N, 2));
  v.Kl = DinoConfig::view_tokens(N, r.uniform(c.local_scale[0], c.local_scale[1]), 1);
  auto runs = [&](std::vector<int>& out, int views, int K) {
    out.resize(std::size_t(views) * B * K);
    for (int i = 0; i < views * B; ++i) {
      const int start = static_cast<int>(r.below(static_cast<std::uint64_t>(N - K + 1)));
      for (int k = 0; k < K; ++k) out[std::size_t(i) * K + k] = start + k;
    }
  };
  runs(v.global, G, v.Kg);
  runs(v.local, L, v.Kl);
  v.ibot.assign(v.global.size(), 0);
  std::vector<int> perm(static_cast<std::size_t>(v.Kg));
  for (int i = 0; i < G * B; ++i) {
    const int m = std::min(v.Kg - 1, static_cast<int>(v.Kg * r.uniform(c.ibot_ratio[0], c.ibot_ratio[1])));
    for (int k = 0; k < v.Kg; ++k) perm[std::size_t(k)] = k;
    for (int k = 0; k < m; ++k) {  // the first m of a Fisher–Yates shuffle
      const int j = k + static_cast<int>(r.below(static_cast<std::uint64_t>(v.Kg - k)));
      std::swap(perm[std::size_t(k)], perm[std::size_t(j)]);
      v.ibot[std::size_t(i) * v.Kg + perm[std::size_t(k)]] = 1;
    }
  }
  for (std::size_t i = 0; i < v.ibot.size(); ++i)
    if (v.ibot[i]) v.ibot_rows.push_back(static_cast<int>(i));
  return v;
}

// The views of samples [first, first + n) of v (a data-parallel rank's shard of the global batch).
inline DinoViews dino_views_shard(const DinoViews& v, int first, int n) {
  require<ShapeError>(first >= 0 && n > 0 && first + n <= v.B, "dino_views_shard: samples [", first, ", ",
                      first + n, ") of ", v.B);
  if (first == 0 && n == v.B) return v;
  DinoViews out;
  out.B = n, out.Kg = v.Kg, out.Kl = v.Kl;
  auto rows = [&](const auto& all, auto& part, int K) {  // view-major [views·B, K] → [views·n, K]
    const std::size_t views = all.size() / (std::size_t(v.B) * K);
    for (std::size_t g = 0; g < views; ++g) {
      const auto from = all.begin() + std::ptrdiff_t((g * v.B + first) * std::size_t(K));
      part.insert(part.end(), from, from + std::ptrdiff_t(std::size_t(n) * K));
    }
  };
  rows(v.global, out.global, v.Kg);
  rows(v.local, out.local, v.Kl);
  rows(v.ibot, out.ibot, v.Kg);
  for (std::size_t i = 0; i < out.ibot.size(); ++i)
    if (out.ibot[i]) out.ibot_rows.push_back(static_cast<int>(i));
  return out;
}

struct DinoStepStats : StepStats {
  double momentum = 0;      // the teacher's EMA momentum this step used
  double teacher_temp = 0;  // τₜ this step used
  double dino = 0, ibot = 0, koleo = 0;

  void write(std::ostream& os) const {
    StepStats::write(os);
    os << " ema " << momentum << " teacher_temp " << teacher_temp << " dino " << dino << " ibot " << ibot << " koleo "
       << koleo;
  }
};

// The DINO collapse that the loss alone shows: a student whose predictions are the uniform
// distribution scores ℓ = ln P against any teacher, and its gradient no longer tells the samples
// apart, so the EMA teacher follows it. True when the class-token loss (DinoStepStats::dino,
// averaged over a run's last steps) is within share of ln P: the run learned nothing from its views.
inline bool dino_collapsed(double dino_loss, int prototypes, double share = 1e-3) {
  require<ConfigError>(prototypes > 1, "dino_collapsed: ", prototypes, " prototypes, expected > 1");
  return dino_loss >= (1.0 - share) * std::log(static_cast<double>(prototypes));
}

// Caller-owned buffers of one step.
template <class T>
struct DinoWorkspace {
  Workspace<T> ws;
  TokenizerCache<T> tokenizer_cache;
  EncoderCache<T> global_cache, local_cache;
  DinoHeadCache<T> student_cache, teacher_cache;
  AlignedVector<T> tokens, tokens_g, tokens_l, teacher_tokens;  // [B | G·B | L·B, N, d]
  AlignedVector<T> out_g, out_l, teacher_out;                   // encoder outputs
  AlignedVector<T> rows, teacher_rows;                          // head inputs [cls; masked]
  AlignedVector<T> logits, teacher_logits, probs, dlogits, drows;
  AlignedVector<T> dout_g, dout_l;
  DinoViews views;
  double dino = 0, ibot = 0, koleo = 0;
  // The teacher's rows of the last forward summed per prototype, then their count: [P + 1] for
  // the class center, then [P + 1] for the patch center. Data parallel, they are summed over the
  // ranks, so that the centers move toward the global batch's mean.
  std::vector<double> center_sums;
  int B = 0;  // the batch of the forward pass held; 0: none
};

// τₜ at step s of a run of `steps`.
inline double dino_teacher_temp(const DinoConfig& c, std::int64_t s, std::int64_t steps) {
  const double warm = c.teacher_warmup * static_cast<double>(steps);
  if (warm <= 0 || static_cast<double>(s) >= warm) return c.teacher_temp[1];
  return c.teacher_temp[0] + (c.teacher_temp[1] - c.teacher_temp[0]) * static_cast<double>(s) / warm;
}

// The DINO loss of batch x [B, N, W] with step s's views; keeps in w what dino_backward needs.
// first_sample: the batch's offset in the global batch (data parallel), so that each rank's
// drop-path noise is its own.
template <class T>
double dino_forward(DinoModel<T>& model, const T* x, int B, const DinoViews& v, double teacher_temp, DinoWorkspace<T>& w,
                    std::uint64_t noise_seed, std::uint64_t first_sample = 0) {
  const DinoConfig& c = model.config;
  const int N = model.num_tokens(), d = model.dim(), G = c.global_views, L = c.local_views, P = c.head.prototypes;
  const int R = c.encoder.register_tokens, Kg = v.Kg, Kl = v.Kl;
  require<ShapeError>(B > 0 && v.B == B, "dino_forward: views for ", v.B, " samples, the batch has ", B);
  require<ShapeError>(B >= 2 || c.koleo_weight == 0, "dino_forward: KoLeo needs at least 2 samples, the batch has ", B);
  w.B = 0;
  const std::size_t BNd = std::size_t(B) * N * d;
  T* tokens = detail::grow(w.tokens, BNd);
  model.tokenizer.forward(model.student, x, B, tokens, w.tokenizer_cache, w.ws);
  auto repeat = [&](AlignedVector<T>& buf, const T* src, int times) {
    T* p = detail::grow(buf, BNd * std::size_t(times));
    for (int i = 0; i < times; ++i) std::copy(src, src + BNd, p + BNd * std::size_t(i));
    return p;
  };
  Rng noise(noise_seed);
  const T* tg = repeat(w.tokens_g, tokens, G);
  T* out_g = detail::grow(w.out_g, std::size_t(G) * B * (R + Kg) * d);
  model.encoder.forward(model.student, {tg, G * B, v.global, v.ibot}, out_g, w.global_cache, w.ws,
                        EncoderOptions{DropPath{c.drop_path, noise(), first_sample * std::uint64_t(G)}, nullptr});
  T* out_l = nullptr;
  if (L > 0) {
    const T* tl = repeat(w.tokens_l, tokens, L);
    out_l = detail::grow(w.out_l, std::size_t(L) * B * (R + Kl) * d);
    model.encoder.forward(model.student, {tl, L * B, v.local}, out_l, w.local_cache, w.ws,
                          EncoderOptions{DropPath{c.drop_path, noise(), first_sample * std::uint64_t(L)}, nullptr});
  }
  // The teacher: its own tokenizer pass, the global views unmasked.
  T* ttok = detail::grow(w.teacher_tokens, BNd * std::size_t(G));
  model.tokenizer.forward(model.teacher, x, B, ttok, w.ws);
  for (int i = 1; i < G; ++i) std::copy(ttok, ttok + BNd, ttok + BNd * std::size_t(i));
  T* tout = detail::grow(w.teacher_out, std::size_t(G) * B * (R + Kg) * d);
  model.encoder.forward(model.teacher, {ttok, G * B, v.global}, tout, w.ws);

  // Head inputs: the class tokens of every view, then the iBOT-masked tokens.
  const int V = G + L, C = V * B, Mp = static_cast<int>(v.ibot_rows.size()), Ms = C + Mp, Mt = G * B + Mp;
  T* rows = detail::grow(w.rows, std::size_t(Ms) * d);
  T* trows = detail::grow(w.teacher_rows, std::size_t(Mt) * d);
  for (int i = 0; i < G * B; ++i) {
    std::copy_n(out_g + std::size_t(i) * (R + Kg) * d, d, rows + std::size_t(i) * d);
    std::copy_n(tout + std::size_t(i) * (R + Kg) * d, d, trows + std::size_t(i) * d);
  }
  for (int i = 0; i < L * B; ++i)
    std::copy_n(out_l + std::size_t(i) * (R + Kl) * d, d, rows + std::size_t(G * B + i) * d);
  for (int p = 0; p < Mp; ++p) {
    const int q = v.ibot_rows[std::size_t(p)], view_row = q / Kg, k = q % Kg;
    const std::size_t at = (std::size_t(view_row) * (R + Kg) + R + k) * d;
    std::copy_n(out_g + at, d, rows + std::size_t(C + p) * d);
    std::copy_n(tout + at, d, trows + std::size_t(G * B + p) * d);
  }
  T* s = detail::grow(w.logits, std::size_t(Ms) * P);
  T* t = detail::grow(w.teacher_logits, std::size_t(Mt) * P);
  model.head.forward(model.student_head, rows, Ms, s, w.student_cache);
  model.head.forward(model.teacher_head, trows, Mt, t, w.teacher_cache);
  T* probs = detail::grow(w.probs, std::size_t(Mt) * P);
  dino_teacher_probs(probs, t, model.centers.value(model.center), G * B, P, teacher_temp);
  if (Mp > 0)
    dino_teacher_probs(probs + std::size_t(G) * B * P, t + std::size_t(G) * B * P,
                       model.centers.value(model.patch_center), Mp, P, teacher_temp);
  T* ds = detail::grow(w.dlogits, std::size_t(Ms) * P);
  std::fill(ds, ds + std::size_t(Ms) * P, T(0));
  // Class tokens: every (student view i, teacher view j ≠ i) pair, each a mean over the batch.
  const int pairs = G * (V - 1);
  double dino = 0;
  for (int i = 0; i < V; ++i)
    for (int j = 0; j < G; ++j) {
      if (i == j) continue;
      const double scale = 1.0 / (double(pairs) * B);
      dino += scale * dino_cross_entropy(s + std::size_t(i) * B * P, probs + std::size_t(j) * B * P, B, P,
                                         c.student_temp, ds + std::size_t(i) * B * P, scale);
    }
  double ibot = 0;
  if (Mp > 0) {
    const double scale = 1.0 / (double(Mp) * G);
    ibot = scale * dino_cross_entropy(s + std::size_t(C) * P, probs + std::size_t(G) * B * P, Mp, P, c.student_temp,
                                      ds + std::size_t(C) * P, scale);
  }
  // KoLeo on the student's global class tokens (the encoder's output, before the head).
  T* drows = detail::grow(w.drows, std::size_t(Ms) * d);
  std::fill(drows, drows + std::size_t(Ms) * d, T(0));
  double koleo = 0;
  if (c.koleo_weight > 0)
    for (int g = 0; g < G; ++g)
      koleo += c.koleo_weight * koleo_loss(rows + std::size_t(g) * B * d, B, d, drows + std::size_t(g) * B * d,
                                           c.koleo_weight);
  w.dino = dino, w.ibot = ibot, w.koleo = koleo;
  // The centers' sums: rows in order, each summed along (no strided reads).
  w.center_sums.assign(2 * (std::size_t(P) + 1), 0.0);
  auto sums = [&](const T* teacher, int M, double* sum) {
    for (int i = 0; i < M; ++i)
      for (int k = 0; k < P; ++k) sum[k] += double(teacher[std::size_t(i) * P + k]);
    sum[P] = M;
  };
  sums(t, G * B, w.center_sums.data());
  sums(t + std::size_t(G) * B * P, Mp, w.center_sums.data() + P + 1);
  w.views = v;
  w.B = B;
  return dino + ibot + koleo;
}

// Adds ∂L/∂θ of the last dino_forward to the student's gradients.
template <class T>
void dino_backward(DinoModel<T>& model, DinoWorkspace<T>& w) {
  require<ConfigError>(w.B > 0, "dino_backward: the workspace holds no forward pass, expected dino_forward first");
  const DinoConfig& c = model.config;
  const DinoViews& v = w.views;
  const int B = w.B, N = model.num_tokens(), d = model.dim(), G = c.global_views, L = c.local_views;
  const int R = c.encoder.register_tokens, Kg = v.Kg, Kl = v.Kl, C = (G + L) * B;
  const int Mp = static_cast<int>(v.ibot_rows.size());
  T* drows = w.drows.data();
  model.head.backward(model.student_head, w.dlogits.data(), w.rows.data(), drows, w.student_cache);
  T* dg = detail::grow(w.dout_g, std::size_t(G) * B * (R + Kg) * d);
  std::fill(dg, dg + std::size_t(G) * B * (R + Kg) * d, T(0));
  for (int i = 0; i < G * B; ++i) std::copy_n(drows + std::size_t(i) * d, d, dg + std::size_t(i) * (R + Kg) * d);
  for (int p = 0; p < Mp; ++p) {
    const int q = v.ibot_rows[std::size_t(p)], view_row = q / Kg, k = q % Kg;
    T* at = dg + (std::size_t(view_row) * (R + Kg) + R + k) * d;
    const T* src = drows + std::size_t(C + p) * d;
    for (int j = 0; j < d; ++j) at[j] += src[j];
  }
  const std::size_t BNd = std::size_t(B) * N * d;
  T* dtg = w.tokens_g.data();  // the repeated tokens are no longer needed: their storage takes the gradient
  std::fill(dtg, dtg + BNd * std::size_t(G), T(0));
  model.encoder.backward(model.student, dg, dtg, w.global_cache, w.ws);
  T* dtokens = w.tokens.data();
  std::fill(dtokens, dtokens + BNd, T(0));
  for (int g = 0; g < G; ++g)
    for (std::size_t i = 0; i < BNd; ++i) dtokens[i] += dtg[BNd * std::size_t(g) + i];
  if (L > 0) {
    T* dl = detail::grow(w.dout_l, std::size_t(L) * B * (R + Kl) * d);
    std::fill(dl, dl + std::size_t(L) * B * (R + Kl) * d, T(0));
    for (int i = 0; i < L * B; ++i)
      std::copy_n(drows + std::size_t(G * B + i) * d, d, dl + std::size_t(i) * (R + Kl) * d);
    T* dtl = w.tokens_l.data();
    std::fill(dtl, dtl + BNd * std::size_t(L), T(0));
    model.encoder.backward(model.student, dl, dtl, w.local_cache, w.ws);
    for (int l = 0; l < L; ++l)
      for (std::size_t i = 0; i < BNd; ++i) dtokens[i] += dtl[BNd * std::size_t(l) + i];
  }
  model.tokenizer.backward(model.student, dtokens, w.tokenizer_cache, w.ws);
  w.B = 0;
}

// The update after dino_backward: the NaN stop and clipping, AdamW, the teacher's EMA, and the
// centers moved toward this step's teacher rows (used from the next step).
template <class T>
DinoStepStats dino_update(DinoModel<T>& model, AdamW<T>& opt, const TrainingSchedule& schedule, std::int64_t s,
                          double loss, DinoWorkspace<T>& w) {
  DinoStepStats st;
  st.dino = w.dino, st.ibot = w.ibot, st.koleo = w.koleo;
  clipped_adamw_step<T>(st, model.trainable(), opt, schedule, s, loss, model.config.clip_grad_norm, "DINO");
  st.momentum = schedule.momentum_at(s);
  ema_update(model.teacher, model.student, st.momentum);
  ema_update(model.teacher_head, model.student_head, st.momentum);
  const int P = model.config.head.prototypes;
  require<ConfigError>(w.center_sums.size() == 2 * (std::size_t(P) + 1), "dino_update: no forward pass's center sums");
  const double m = model.config.center_momentum;
  auto move = [&](ParamId id, const double* sum) {
    const double M = sum[P];
    if (M <= 0) return;
    T* cen = model.centers.value(id);
    for (int k = 0; k < P; ++k) cen[k] = T(m * double(cen[k]) + (1 - m) * sum[k] / M);
  };
  move(model.center, w.center_sums.data());
  move(model.patch_center, w.center_sums.data() + P + 1);
  return st;
}

// DINO pre-training as an Objective (train/objective.hpp), with the data order, schedule and
// AdamW of a JepaObjective of the same TrainConfig. Checkpoint metadata: {"objective": "dino",
// "train": cfg, "dino": config}.
// Data parallel as the reference (DINOv2 under DistributedDataParallel) runs it: each rank draws
// the global batch's views and keeps its shard's; the DINO and iBOT losses and KoLeo are its
// shard's (KoLeo's neighbours are the shard's samples); gradients and losses are averaged over
// the global batch; the centers move toward the global batch's teacher mean (the rows' sums and
// counts summed over the ranks).
template <class T, class Source = WindowSource>
class DinoObjective {
 public:
  using value_type = T;
  using stats_type = DinoStepStats;

  DinoObjective(DinoModel<T>& model, const Source& source, TrainConfig config)
      : data((config.validate(), source), config.seed, config.batch), model_(model), cfg_(std::move(config)),
        optimizer_(model.trainable(), cfg_.adamw), schedule_(cfg_.schedule.build()) {}
  DinoObjective(const DinoObjective&) = delete;
  DinoObjective& operator=(const DinoObjective&) = delete;

  WindowBatches<T, Source> data;

  DinoModel<T>& model() { return model_; }
  const TrainConfig& config() const { return cfg_; }
  DinoWorkspace<T>& workspace() { return w_; }

  std::int64_t num_samples() const { return data.size(); }
  int batch_size() const { return cfg_.batch; }
  std::int64_t total_steps() const { return schedule_.total_steps(); }
  std::vector<std::int64_t> epoch_order(std::uint64_t epoch) const { return data.epoch_order(epoch); }
  void zero_grad() {
    model_.student.zero_grad();
    model_.student_head.zero_grad();
  }
  double forward(const StepBatch& b) {
    require<ConfigError>(model_.config.group_size.empty() || data.to_tokens,
                         "DinoObjective: a grouped tokenizer needs its own data.to_tokens");
    const T* x = data.tokens(b.ids, model_.num_tokens(), model_.token_width());
    DinoViews v = sample_dino_views(model_.config, b.batch, streams::masks(cfg_.seed), static_cast<std::uint64_t>(b.step));
    if (b.size() != b.batch) v = dino_views_shard(v, b.first, b.size());
    teacher_temp_ = dino_teacher_temp(model_.config, b.step, total_steps());
    loss_ = dino_forward(model_, x, b.size(), v, teacher_temp_, w_, streams::noise(cfg_.seed, b.step),
                         static_cast<std::uint64_t>(b.first));
    return loss_;
  }
  void backward() { dino_backward(model_, w_); }
  void all_reduce(const DataParallel<T>& dp, int count, int B) {
    double stats[4] = {loss_, w_.dino, w_.ibot, w_.koleo};
    const auto parts = model_.trainable();
    all_reduce_mean<T>(parts, stats, dp, count, B);
    loss_ = stats[0], w_.dino = stats[1], w_.ibot = stats[2], w_.koleo = stats[3];
    dp.sum_stats(w_.center_sums);
  }
  DinoStepStats update(std::int64_t s) {
    DinoStepStats st = dino_update(model_, optimizer_, schedule_, s, loss_, w_);
    st.teacher_temp = teacher_temp_;
    return st;
  }
  std::vector<PrefixedParams<T>> parts() { return model_.parts(); }
  AdamW<T>& optimizer() { return optimizer_; }
  nlohmann::json metadata() const {
    return {{"objective", "dino"}, {"train", cfg_.to_json()}, {"dino", model_.config.to_json()}};
  }

 private:
  DinoModel<T>& model_;
  TrainConfig cfg_;
  AdamW<T> optimizer_;
  TrainingSchedule schedule_;
  DinoWorkspace<T> w_;
  double loss_ = 0, teacher_temp_ = 0;
};

template <class T, class Source = WindowSource>
using DinoTrainer = Trainer<DinoObjective<T, Source>>;

}  // namespace tjepa
