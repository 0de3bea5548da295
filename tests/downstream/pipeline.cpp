// Pipeline (downstream/pipeline.hpp): frame by frame, the embeddings and head outputs of exactly
// the windows a WindowSource cuts from the same recording (drift tracked, preprocessed, every
// stride frames), in the recording's column order; no allocation after the first window; a gap
// restarts the window; bad frames, a head of another encoder or another tau refused by name.
#include <doctest/doctest.h>

#include <tjepa/downstream/pipeline.hpp>
#include <tjepa/tjepa.hpp>

#include <allocation_counter.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <string>
#include <vector>

using namespace tjepa;

TEST_SUITE("downstream") {

namespace {

constexpr int pipe_N = 7, pipe_m = 3, pipe_tau = 4;
constexpr std::size_t frame_size = pipe_N * pipe_m;

// A small trained-model stand-in: random weights, per-axis standardization fitted on `rec`, drift
// tracking fitted on its first frames.
TrainedModel pipeline_model(const Recording& rec, std::uint64_t seed) {
  TrainedModel tm;
  tm.config.data.tau = pipe_tau;
  tm.config.model.dim = 12;
  tm.config.model.depth = 2;
  tm.config.model.heads = 3;
  tm.model = std::make_unique<JepaModel<float>>(tm.config.model_config(pipe_N, pipe_m), seed);
  Preprocessor pre(PreprocessConfig::baseline_standardization());
  Recording rest(20, pipe_N, pipe_m);
  for (int t = 0; t < 20; ++t)
    for (int n = 0; n < pipe_N; ++n)
      for (int a = 0; a < pipe_m; ++a) rest.at(t, n, a) = rec(t, n, a);
  pre.fit_baseline(rest);
  pre.fit(rec);
  tm.pre = std::move(pre);
  DriftTracker drift;
  drift.fit(rest);
  tm.drift = std::move(drift);
  return tm;
}

// A recording [T, N, m] with slow drift and touches.
Recording pipeline_recording(int T, std::uint64_t seed) {
  Rng rng(seed);
  Recording r(T, pipe_N, pipe_m);
  for (int t = 0; t < T; ++t)
    for (int n = 0; n < pipe_N; ++n)
      for (int a = 0; a < pipe_m; ++a)
        r.at(t, n, a) = static_cast<float>(100.0 * n + 10.0 * a + 0.02 * t + rng.normal() +
                                           (t > 30 && (t / 9 + n) % 3 == 0 ? 25.0 * std::sin(0.3 * t + n) : 0.0));
  return r;
}

// What `tjepa embed` computes: the windows of the whole (tracked) recording, embedded in a batch.
AlignedVector<float> offline_embeddings(TrainedModel& tm, const Recording& layout_rec, int stride,
                                        std::vector<std::int64_t>& starts) {
  Recording rec = layout_rec;
  tm.track(rec);
  const WindowSource src(rec, WindowSpec{.length = pipe_tau, .stride = stride}, {}, tm.pre);
  std::vector<std::int64_t> ids(static_cast<std::size_t>(src.size()));
  std::iota(ids.begin(), ids.end(), 0);
  for (std::int64_t w : ids) starts.push_back(src.start_of(w));
  return embed_windows(tm.model->target, tm.model->tokenizer, tm.model->encoder, src, ids, 5);
}

double max_abs_diff(std::span<const float> a, std::span<const float> b) {
  double e = 0;
  for (std::size_t k = 0; k < a.size(); ++k) e = std::max(e, std::abs(static_cast<double>(a[k]) - b[k]));
  return e;
}

}  // namespace

TEST_CASE("Pipeline: the windows of WindowSource frame by frame / the recording's column order in and out / no allocation after the first window") {
  const Recording rec = pipeline_recording(60, 3);
  // The layout reads the recording's columns in this order (column[i]: layout taxel i's column).
  const std::vector<int> column{3, 0, 6, 1, 5, 2, 4};
  const Recording layout_rec = select_taxels(rec, column);
  TrainedModel reference = pipeline_model(layout_rec, 11);
  std::vector<std::int64_t> starts;
  const int stride = 3;
  const AlignedVector<float> offline = offline_embeddings(reference, layout_rec, stride, starts);
  const int d = reference.model->dim();
  const std::size_t per = static_cast<std::size_t>(pipe_N) * d;

  Pipeline p(pipeline_model(layout_rec, 11), std::nullopt, PipelineConfig{.column = column, .stride = stride});
  CHECK(p.tau() == pipe_tau);
  CHECK(p.axes() == pipe_m);
  std::size_t w = 0;
  long steady = 0;
  for (int t = 0; t < rec.frames(); ++t) {
    const std::span<const float> frame(rec.frame(t), static_cast<std::size_t>(pipe_N) * pipe_m);
    const PipelineOutput* o = nullptr;
    if (w >= 1)
      steady += alloc::count_allocations([&] { o = p.push(frame); });
    else
      o = p.push(frame);
    if (!o) continue;
    REQUIRE(w < starts.size());
    CHECK(o->frame == starts[w] + pipe_tau - 1);
    CHECK(o->label == -1);
    CHECK(o->outputs.empty());
    // Row c of the output is the recording's column c, which is layout taxel i with column[i] = c.
    std::vector<float> expected(per);
    for (int i = 0; i < pipe_N; ++i)
      std::copy_n(offline.data() + w * per + static_cast<std::size_t>(i) * d, d,
                  expected.data() + static_cast<std::size_t>(column[static_cast<std::size_t>(i)]) * d);
    CHECK(max_abs_diff(o->embedding, expected) < 1e-5);
    ++w;
  }
  CHECK(w == starts.size());
  MESSAGE(std::string(alloc::counts_malloc() ? "counted operator new and malloc" : "counted operator new only (sanitizer)"));
  CHECK(steady == 0);
  // The counter is live.
  CHECK(alloc::count_allocations([] { std::vector<int> v(100); }) > 0);
}

TEST_CASE("Pipeline with a head: outputs of the head on the same embeddings / units and probabilities / restart after a gap") {
  const Recording rec = pipeline_recording(48, 5);
  TrainedModel reference = pipeline_model(rec, 13);
  std::vector<std::int64_t> starts;
  const AlignedVector<float> offline = offline_embeddings(reference, rec, 2, starts);
  const int d = reference.model->dim();
  const std::size_t per = static_cast<std::size_t>(pipe_N) * d;

  ProbeHead<float> head(d, 3, 2, 3, 21);
  head.scaler.mean = {10.0, -1.0};
  head.scaler.std = {2.0, 0.5};
  HeadInfo info;
  info.task = "classification";
  info.class_names = {"a", "b", "c"};
  info.tau = pipe_tau;
  info.stride = 2;
  info.encoder = encoder_fingerprint(reference, reference.model->target);
  info.center_shift.assign(per, 0.0f);
  for (std::size_t k = 0; k < per; ++k) info.center_shift[k] = 0.01f * static_cast<float>(k % 17);
  // The head's outputs on the offline embeddings, as `tjepa probe` computes them.
  const int S = static_cast<int>(starts.size());
  AlignedVector<float> shifted(offline.begin(), offline.end());
  for (std::size_t k = 0; k < shifted.size(); ++k) shifted[k] += info.center_shift[k % per];
  std::vector<float> y(static_cast<std::size_t>(S) * 5);
  Workspace<float> ws;
  head.probe.forward(head.params, {shifted.data(), S, pipe_N}, y.data(), ws);

  Pipeline p(pipeline_model(rec, 13), LoadedProbeHead<float>{head, info});
  CHECK(p.stride() == 2);  // the head's
  CHECK(p.outputs() == 5);
  int w = 0;
  for (int t = 0; t < rec.frames(); ++t) {
    const PipelineOutput* o = p.push({rec.frame(t), frame_size});
    if (!o) continue;
    const float* yw = y.data() + static_cast<std::size_t>(w) * 5;
    CHECK(o->outputs[0] == doctest::Approx(yw[0] * 2.0 + 10.0).epsilon(1e-4));
    CHECK(o->outputs[1] == doctest::Approx(yw[1] * 0.5 - 1.0).epsilon(1e-4));
    const int best = static_cast<int>(std::max_element(yw + 2, yw + 5) - (yw + 2));
    CHECK(o->label == best);
    double sum = 0;
    for (int c = 0; c < 3; ++c) sum += o->outputs[2 + static_cast<std::size_t>(c)];
    CHECK(sum == doctest::Approx(1.0).epsilon(1e-6));
    ++w;
  }
  CHECK(w == S);
  // After a gap the next window needs tau new frames: none is built across it.
  p.restart();
  for (int k = 0; k < pipe_tau - 1; ++k) CHECK(p.push({rec.frame(k), frame_size}) == nullptr);
  CHECK(p.push({rec.frame(pipe_tau - 1), frame_size}) != nullptr);
}

TEST_CASE("Pipeline refuses by name: a frame of another size / a NaN reading / a head of another encoder or tau / a bad column map") {
  const Recording rec = pipeline_recording(30, 7);
  TrainedModel reference = pipeline_model(rec, 17);
  const int d = reference.model->dim();
  Pipeline p(pipeline_model(rec, 17));
  std::vector<float> frame(rec.frame(0), rec.frame(0) + pipe_N * pipe_m);
  CHECK_THROWS_WITH_AS(p.push(std::span<const float>(frame.data(), frame.size() - 1)),
                       doctest::Contains("a frame of 20 values, expected 7 taxels x 3 axes"), ShapeError);
  frame[5] = std::numeric_limits<float>::quiet_NaN();
  CHECK_THROWS_WITH_AS(p.push(frame), doctest::Contains("frame 0: column 1 axis 2 reads nan"), DataError);
  CHECK(p.frames() == 0);

  ProbeHead<float> head(d, 3, 1, 0, 3);
  HeadInfo info;
  info.tau = pipe_tau;
  info.stride = 1;
  // The context encoder after some training: no longer its EMA copy's twin.
  auto trained = [&] {
    TrainedModel tm = pipeline_model(rec, 17);
    for (float& v : tm.model->context.values()) v *= 1.01f;
    return tm;
  };
  info.encoder = encoder_fingerprint(trained(), trained().model->context);
  info.encoder_file = "run.safetensors";
  CHECK_THROWS_WITH_AS(Pipeline(trained(), LoadedProbeHead<float>{head, info}),
                       doctest::Contains("the head reads the model's context encoder"), ConfigError);
  CHECK_NOTHROW(Pipeline(trained(), LoadedProbeHead<float>{head, info}, {.column = {}, .stride = 0, .target_encoder = false}));
  // A model that tracked drift over a recording is still the encoder the head was trained on.
  TrainedModel tracked = trained();
  Recording copy = rec;
  tracked.track(copy);
  CHECK(encoder_fingerprint(tracked, tracked.model->context) == info.encoder);
  info.encoder = "0123456789abcdef";
  CHECK_THROWS_WITH_AS(Pipeline(pipeline_model(rec, 17), LoadedProbeHead<float>{head, info}),
                       doctest::Contains("trained on encoder 0123456789abcdef (run.safetensors)"), ConfigError);
  info.encoder.clear();
  info.tau = pipe_tau + 1;
  CHECK_THROWS_WITH_AS(Pipeline(pipeline_model(rec, 17), LoadedProbeHead<float>{head, info}),
                       doctest::Contains("windows of 5 frames, the model's are 4"), ConfigError);
  CHECK_THROWS_WITH_AS(Pipeline(pipeline_model(rec, 17), std::nullopt, {.column = {0, 1, 2, 3, 4, 5, 5}}),
                       doctest::Contains("column[6] = 5"), ConfigError);
  CHECK_THROWS_AS(Pipeline(pipeline_model(rec, 17), std::nullopt, {.column = {0, 1}}), ShapeError);
}
}
