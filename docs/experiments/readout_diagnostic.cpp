// Diagnostics of docs/history/evaluation-log.md ("Where the pose and the force are"): the grasp
// protocol's data (GraspEvalConfig defaults), one encoder at a time. A throwaway driver kept so that
// the numbers quoted there can be rerun; the protocol's own read-outs are in tjepa eval's linear
// table (score_linear_readouts). Build from the repository root:
//   g++ -std=gnu++20 -O2 -DNDEBUG -march=native -fopenmp -Iinclude -isystem /usr/include/eigen3 \
//       docs/experiments/readout_diagnostic.cpp -o /tmp/readout_diagnostic
// Modes (ENCODER: "random" for the random initial encoder of seed 0, or a checkpoint from "pretrain"):
//   pretrain FILE [SEED]    Tactile-JEPA, 3000 bf16 steps, grasp_pretrain_config(); saves the target encoder
//   rawpose x               ridge on raw window features: pad sums, taxel means, both
//   diag ENCODER            ridge on pad-mean embeddings (label pad only, all pads) for each task
//   context                 ridge from raw window features to the label pad's force: the label pad's own,
//                           every other pad's, all (how much of its shear the rest of the hand predicts)
//   pcapose ENCODER         ridge on per-token residuals projected on k = 1, 3, 8 principal directions
//   seq ENCODER             the sequence head's learning curves (patience 5, 20; lr 3e-4), head seeds 0, 1
//                           (POOL=taxel K=3: the taxel pooling; QUICK=1: the protocol's limits at head
//                           seeds 0, 1, then patience 20 / 100 epochs at seed 0)
//   heads ENCODER           the three heads of the protocol, head seeds 0, 1 (CENTER=1: center_token_embeddings first)
//   object ENCODER [SEED]   the object probe's learning curves at the protocol's limits, head seeds SEED*1000 + 0..2
//                           (as tjepa eval's); STD=1: on standardize_channels'd embeddings; LR=x: another peak lr;
//                           SPLIT=k: each head with the validation split and data order of head (i + k) mod 3;
//                           ERR=1: early stopping on the validation top-1 error (HeadTrainConfig::stop_on_error);
//                           PATIENCE=n, VFRAC=x: the patience and the validation share
// TRAIN_FRAMES=n (any mode): a longer or shorter labelled training recording
// DEPTH=k (modes with ENCODER): read the embeddings after the encoder's first k blocks (k = 0: the
// tokens and position table through the final norm)
// ENCODER may be a --pretrain-cache file of tjepa eval (its parameters are under "encoder.").
#include <tjepa/eval.hpp>
#include <cstdio>
#include <iostream>
using namespace tjepa;

int main(int argc, char** argv) {
  std::string mode = argv[1];
  GraspEvalConfig c;
  c.train.precision = "bf16";
  c.train.steps = 3000;
  if (const char* v = std::getenv("TRAIN_FRAMES")) c.train_frames = std::atoi(v);  // labelled training frames
  auto t0 = std::chrono::steady_clock::now();
  const GraspEvalData d = simulate_grasp_eval_data(c);
  const GraspTasks &tr = d.train_tasks, &te = d.test_tasks;
  const int axes = d.pretrain->axes();
  const TaxelGraph& graph = d.skin.graph;
  // The ridge baseline's features (pad sums, then taxel means) of the task rows asked for.
  auto raw_features = [&](bool test, std::span<const std::int64_t> rows) {
    const GraspTasks& t = test ? te : tr;
    std::vector<std::int64_t> ids;
    for (std::int64_t r : rows) ids.push_back(t.windows[static_cast<std::size_t>(r)]);
    WindowBatch wb;
    (test ? *d.test : *d.train).gather(ids, wb);
    return window_features(wb, d.skin.layout.group, d.skin.layout.num_groups());
  };
  if (mode == "rawpose") {
    const int G = d.skin.layout.num_groups();
    for (int which = 0; which < 3; ++which) {
      auto features = [&](bool test, std::span<const std::int64_t> rows) {
        Eigen::MatrixXd f = raw_features(test, rows);
        const int m = axes;
        if (which == 0) return Eigen::MatrixXd(f.leftCols(G * m));
        if (which == 1) return Eigen::MatrixXd(f.rightCols(f.cols() - G * m));
        return f;
      };
      GraspScores sc = score_ridge_on(features, tr, te, 0);
      std::printf("%s: object %.1f force %.3f pose x %.3f y %.3f th %.2f\n", which == 0 ? "pad sums" : which == 1 ? "taxel means" : "both",
                  sc[kObjectAccuracy], sc[kForceRmse], sc[kPoseX], sc[kPoseY], sc[kPoseTheta]);
    }
    return 0;
  }
  if (mode == "context") {
    // How much of the label pad's force the raw windows predict linearly: ridge on the label pad's
    // own features (its pad sums and taxel means), on every other pad's, and on all of them.
    const auto& group = d.skin.layout.group;
    const int G = d.skin.layout.num_groups(), N = static_cast<int>(group.size()), m = axes;
    const int own = c.tasks.label_pad;
    for (int which = 0; which < 3; ++which) {  // 0: own pad, 1: other pads, 2: all
      std::vector<Eigen::Index> cols;
      auto keep = [&](int pad) { return which == 2 || (which == 0) == (pad == own); };
      for (int g = 0; g < G; ++g)
        if (keep(g))
          for (int a = 0; a < m; ++a) cols.push_back(Eigen::Index(g) * m + a);
      for (int n = 0; n < N; ++n)
        if (keep(group[n]))
          for (int a = 0; a < m; ++a) cols.push_back(Eigen::Index(G) * m + Eigen::Index(n) * m + a);
      auto features = [&](bool test, std::span<const std::int64_t> rows) {
        const Eigen::MatrixXd f = raw_features(test, rows);
        Eigen::MatrixXd out(f.rows(), Eigen::Index(cols.size()));
        for (std::size_t j = 0; j < cols.size(); ++j) out.col(Eigen::Index(j)) = f.col(cols[j]);
        return out;
      };
      const GraspScores sc = score_ridge_on(features, tr, te, 0);  // the force task's fit is the one read here
      std::printf("force ridge on raw %s (%zu features): RMSE %.3f N (shear u %.3f, shear v %.3f, normal %.3f)\n",
                  which == 0 ? "label pad" : which == 1 ? "other pads" : "all pads", cols.size(), sc[kForceRmse],
                  sc[kForceRmseU], sc[kForceRmseV], sc[kForceRmseN]);
    }
    return 0;
  }
  std::uint64_t s = argc > 3 ? std::stoull(argv[3]) : 0;
  TrainConfig cfg = c.train;
  cfg.seed = s;
  auto model = make_jepa_model<float>(cfg, graph, axes, s);
  if (mode == "pretrain") {
    MaskCollator collator(graph, cfg.masks());
    JepaTrainer<float> trainer(*model, *d.pretrain, std::move(collator), cfg);
    trainer.on_step = [&](const JepaStepStats& st) {
      if ((st.step + 1) % 300 == 0) std::printf("step %ld loss %g std %g\n", long(st.step + 1), st.loss, st.target_sample_std), fflush(stdout);
    };
    trainer.run();
    save_checkpoint<float>(argv[2], {{"target.", &model->target}}, nullptr, CheckpointState{});
    return 0;
  }
  if (std::string(argv[2]) != "random") {
    const std::string file = argv[2];
    const bool cached = file.find(".safetensors") != std::string::npos && file.find("-seed") != std::string::npos;
    load_checkpoint<float>(file, {{cached ? "encoder." : "target.", &model->target}}, nullptr);
  }
  if (const char* v = std::getenv("DEPTH")) {
    // The embeddings after the first DEPTH blocks: the later blocks' residual branches (attn.proj,
    // mlp.fc2) are zeroed, so those blocks pass x through and the final norm reads block DEPTH's output.
    const int keep = std::atoi(v);
    require<ConfigError>(keep >= 0 && keep <= cfg.depth, "DEPTH = ", v, ", expected 0 ... ", cfg.depth);
    for (int b = keep; b < cfg.depth; ++b)
      for (const char* p : {"attn.proj.weight", "attn.proj.bias", "mlp.fc2.weight", "mlp.fc2.bias"}) {
        auto w = model->target.value_span(model->target.id("blocks." + std::to_string(b) + "." + p));
        std::fill(w.begin(), w.end(), 0.0f);
      }
    std::printf("depth %d of %d\n", keep, cfg.depth);
  }
  const int N = model->encoder.num_tokens(), dd = model->encoder.dim();
  AlignedVector<float> etr = embed_windows(model->target, model->tokenizer, model->encoder, *d.train, tr.windows);
  AlignedVector<float> ete = embed_windows(model->target, model->tokenizer, model->encoder, *d.test, te.windows);
  if (std::getenv("CENTER")) {
    std::span<float> o(ete.data(), ete.size());
    center_token_embeddings<float>(std::span<float>(etr.data(), etr.size()), std::span<const std::span<float>>(&o, 1), N, dd);
    std::printf("centered\n");
  }
  if (std::getenv("STD")) {
    std::span<float> o(ete.data(), ete.size());
    standardize_channels<float>(std::span<float>(etr.data(), etr.size()), std::span<const std::span<float>>(&o, 1), dd);
    std::printf("standardized\n");
  }
  FrozenFeatures<float> ftr(std::move(etr), N, dd);
  FrozenFeatures<float> fte(std::move(ete), N, dd);
  if (mode == "pcapose") {
    // Per-token linear read-out: each token's embedding minus its training mean, projected on the
    // top-k principal directions of those residuals; ridge on the N*k features.
    auto etr_ = ftr.embeddings();
    auto ete_ = fte.embeddings();
    const std::size_t per = std::size_t(N) * dd;
    const std::size_t S = etr_.size() / per;
    std::vector<double> mu(per, 0.0);
    for (std::size_t s2 = 0; s2 < S; ++s2) for (std::size_t i = 0; i < per; ++i) mu[i] += etr_[s2 * per + i];
    for (double& v : mu) v /= double(S);
    Eigen::MatrixXd C = Eigen::MatrixXd::Zero(dd, dd);
    Eigen::VectorXd r(dd);
    for (std::size_t s2 = 0; s2 < S; s2 += 4)
      for (int n = 0; n < N; ++n) {
        for (int i = 0; i < dd; ++i) r(i) = etr_[s2 * per + std::size_t(n) * dd + i] - mu[std::size_t(n) * dd + i];
        C.selfadjointView<Eigen::Lower>().rankUpdate(r);
      }
    C = C.selfadjointView<Eigen::Lower>();
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(C);
    const Eigen::VectorXd ev = es.eigenvalues().reverse();
    std::printf("top eigenvalue shares:");
    for (int i = 0; i < 8; ++i) std::printf(" %.3f", ev(i) / ev.sum());
    std::printf("\n");
    for (int k : {1, 3, 8}) {
      const Eigen::MatrixXd U = es.eigenvectors().rightCols(k);
      auto features = [&](bool test, std::span<const std::int64_t> rows) {
        auto e = test ? ete_ : etr_;
        Eigen::MatrixXd f(Eigen::Index(rows.size()), Eigen::Index(N) * k);
        for (std::size_t q = 0; q < rows.size(); ++q)
          for (int n = 0; n < N; ++n) {
            for (int i = 0; i < dd; ++i) r(i) = e[std::size_t(rows[q]) * per + std::size_t(n) * dd + i] - mu[std::size_t(n) * dd + i];
            f.block(Eigen::Index(q), Eigen::Index(n) * k, 1, k) = (r.transpose() * U);
          }
        return f;
      };
      GraspScores sc = score_ridge_on(features, tr, te, 0);
      std::printf("pca k=%d: object %.1f force %.3f pose x %.3f y %.3f th %.2f\n", k, sc[kObjectAccuracy], sc[kForceRmse], sc[kPoseX], sc[kPoseY], sc[kPoseTheta]);
      fflush(stdout);
    }
    return 0;
  }
  if (mode == "object") {
    GraspHeadConfig hc;
    HeadTrainConfig h = hc.probe;
    if (const char* lr = std::getenv("LR")) h.lr = std::atof(lr);
    if (std::getenv("ERR")) h.stop_on_error = true;
    if (const char* v = std::getenv("PATIENCE")) h.patience = std::atoi(v);
    if (const char* v = std::getenv("VFRAC")) h.validation_fraction = std::atof(v);
    // SPLIT=k: head i keeps its initialization but takes the validation split and data order of
    // head (i + k) mod 3.
    const std::uint64_t split = std::getenv("SPLIT") ? std::stoull(std::getenv("SPLIT")) : 0;
    for (std::uint64_t i = 0; i < 3; ++i) {
      h.seed = s * 1000 + (i + split) % 3;
      RowFeatures rtr(ftr, tr.object_rows), rte(fte, te.object_rows);
      ProbeHead<float> head(dd, hc.probe_heads, 0, tr.object.classes, (s * 1000 + i) ^ 0x6f626a656374ull, 0,
                            PoolingConfig{.tokens = N});
      const HeadTrainResult r = train_head(head, rtr, tr.object, h);
      const std::vector<float> y = predict_head(head, rte, rte.size());
      std::vector<int> cls(static_cast<std::size_t>(rte.size()));
      for (std::size_t q = 0; q < cls.size(); ++q) cls[q] = argmax(y.data() + q * head.outputs(), head.outputs());
      GraspScores sc{};
      score_object(sc, cls, te);
      std::printf("head seed %lu (split and order %lu): top-1 %.1f %%, epochs %d, best %d | train/validation:",
                  (unsigned long)(s * 1000 + i), (unsigned long)h.seed,
                  sc[kObjectAccuracy], r.epochs(), r.best_epoch);
      for (int e = 0; e < r.epochs(); e += 3) std::printf(" %.2f/%.2f", r.train_loss[e], r.validation_loss[e]);
      std::printf("\n");
      fflush(stdout);
    }
    return 0;
  }
  if (mode == "heads") {
    GraspHeadConfig hc;
    for (std::uint64_t hs : {0, 1}) {
      GraspScores sc = score_heads<float>([&](int) { return std::pair{&ftr, &fte}; }, tr, te, hc, false, hs,
                                          [](const std::string& s) { std::printf("  %s\n", s.c_str()); fflush(stdout); });
      (void)sc;
    }
    return 0;
  }
  std::printf("embedded %zu+%zu in %.1f s\n", tr.windows.size(), te.windows.size(),
              std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());

  if (mode == "diag") {
    // Linear read-outs of frozen features: ridge on pad-pooled token embeddings.
    const auto& group = d.skin.layout.group;
    const int G = d.skin.layout.num_groups();
    auto pooled = [&](FrozenFeatures<float>& f, std::span<const std::int64_t> rows, int only_pad) {
      const int P = only_pad >= 0 ? 1 : G;
      Eigen::MatrixXd X = Eigen::MatrixXd::Zero(Eigen::Index(rows.size()), Eigen::Index(P) * dd);
      std::vector<int> cnt(G, 0);
      for (int n = 0; n < N; ++n) cnt[group[n]]++;
      auto e = f.embeddings();
      for (std::size_t r = 0; r < rows.size(); ++r)
        for (int n = 0; n < N; ++n) {
          const int g = group[n];
          if (only_pad >= 0 && g != only_pad) continue;
          const int col = only_pad >= 0 ? 0 : g;
          const float* x = e.data() + (std::size_t(rows[r]) * N + n) * dd;
          for (int i = 0; i < dd; ++i) X(Eigen::Index(r), Eigen::Index(col) * dd + i) += x[i] / cnt[g];
        }
      return X;
    };
    auto targets = [](const std::vector<float>& v) {
      Eigen::MatrixXd y(static_cast<Eigen::Index>(v.size() / 3), 3);
      for (Eigen::Index i = 0; i < y.rows(); ++i)
        for (int a = 0; a < 3; ++a) y(i, a) = v[static_cast<std::size_t>(i) * 3 + a];
      return y;
    };
    static constexpr std::array<double, 9> lambdas{1e-2, 1e-1, 1, 10, 1e2, 1e3, 1e4, 1e5, 1e6};
    for (int pad : {c.tasks.label_pad, -1}) {
      const RidgeModel m = fit_ridge(pooled(ftr, tr.force_rows, pad), targets(tr.force.value), lambdas, 0.2, 0, tr.force.groups);
      const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> y = predict(m, pooled(fte, te.force_rows, pad));
      GraspScores sc{};
      score_force(sc, y.data(), 3, te);
      std::printf("force ridge on %s: RMSE %.3f N (shear u %.3f, shear v %.3f, normal %.3f)\n",
                  pad >= 0 ? "label pad mean" : "all pad means", sc[kForceRmse], sc[kForceRmseU], sc[kForceRmseV],
                  sc[kForceRmseN]);
    }
    {
      const RidgeModel m = fit_ridge_classifier(pooled(ftr, tr.object_rows, -1), tr.object.label, tr.object.classes, lambdas, 0.2, 0, tr.object.groups);
      GraspScores sc{};
      score_object(sc, predict_class(m, pooled(fte, te.object_rows, -1)), te);
      std::printf("object ridge on pad means: %.1f %%\n", sc[kObjectAccuracy]);
    }
    {
      SampleGroups per_window;
      for (std::size_t q = 0; q < tr.pose.groups.group.size(); ++q)
        for (int l = 0; l < tr.pose.length; ++l) {
          per_window.group.push_back(tr.pose.groups.group[q]);
          if (!tr.pose.groups.stratum.empty()) per_window.stratum.push_back(tr.pose.groups.stratum[q]);
        }
      const RidgeModel m = fit_ridge(pooled(ftr, tr.pose.window, -1), targets(tr.pose.value), lambdas, 0.2, 0, per_window);
      const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> y = predict(m, pooled(fte, te.pose.window, -1));
      GraspScores sc{};
      score_pose(sc, y.data(), 3, te);
      std::printf("pose ridge on pad means: x %.3f y %.3f th %.2f\n", sc[kPoseX], sc[kPoseY], sc[kPoseTheta]);
    }
    return 0;
  }
  auto run_seq = [&](const char* name, HeadTrainConfig h, std::uint64_t hs) {
    h.seed = hs;
    SequenceHeadConfig hc;
    hc.dim = dd; hc.heads = 3; hc.length = tr.pose.length; hc.outputs = 3;
    if (const char* p = std::getenv("POOL")) hc.pooling.kind = parse_pooling(p);
    hc.pooling.tokens = N;
    if (const char* k = std::getenv("K")) hc.pooling.components = std::atoi(k);
    SequenceModel<float> m(hc, hs ^ 0x706f7365ull);
    auto r = train_sequence_head(m, ftr, tr.pose, h);
    const std::vector<float> y = predict_sequence_head(m, fte, te.pose);
    GraspScores sc{};
    score_pose(sc, y.data(), 3, te);
    std::printf("%s seed %lu: epochs %d best %d  x %.3f y %.3f th %.2f | train:", name, (unsigned long)hs, r.epochs(), r.best_epoch,
                sc[kPoseX], sc[kPoseY], sc[kPoseTheta]);
    for (int e = 0; e < r.epochs(); ++e) std::printf(" %.3f/%.3f", r.train_loss[e], r.validation_loss[e]);
    std::printf("\n");
    fflush(stdout);
  };
  GraspHeadConfig base;
  base.sequence.patience = 5;  // the sequence head's limits before the eleventh session
  base.sequence.max_epochs = 40;
  if (std::getenv("QUICK")) {  // those limits, then patience 20 / 100 epochs (the protocol's since)
    for (std::uint64_t hs : {0, 1}) run_seq("default p5", base.sequence, hs);
    HeadTrainConfig h = base.sequence; h.patience = 20; h.max_epochs = 100;
    run_seq("p20 e100", h, 0);
    return 0;
  }
  for (std::uint64_t hs : {0, 1}) {
    run_seq("default p5", base.sequence, hs);
    HeadTrainConfig h = base.sequence; h.patience = 20; h.max_epochs = 60;
    run_seq("p20 e60", h, hs);
    h = base.sequence; h.lr = 3e-4; h.patience = 20; h.max_epochs = 60;
    run_seq("lr3e-4 p20", h, hs);
  }
  return 0;
}
