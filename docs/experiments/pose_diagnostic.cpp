#include <tjepa/eval.hpp>
#include <cstdio>
using namespace tjepa;
// Pose diagnostic for docs/history/evaluation-log.md: how much of the pose do the contacts' centroids
// hold, and how does the sequence head train on a random encoder's features without early
// stopping? Build and run from the repository root:
//   g++ -std=c++20 -O2 -march=native -fopenmp -Iinclude -I/usr/include/eigen3 \
//       docs/experiments/pose_diagnostic.cpp -o /tmp/pose_diagnostic && OMP_NUM_THREADS=1 /tmp/pose_diagnostic
int main() {
  GraspEvalConfig c;
  const GraspEvalData d = simulate_grasp_eval_data(c);
  const auto& L = d.skin.layout;
  const int G = L.num_groups(), N = d.skin.size();
  auto centroid_features = [&](const WindowSource& src, const GraspTasks& t) {
    std::vector<std::int64_t> ids;
    for (auto r : t.pose.window) ids.push_back(t.windows[r]);
    WindowBatch wb;
    src.gather(ids, wb);
    Eigen::MatrixXd X = Eigen::MatrixXd::Zero(wb.batch, G * 3);
    for (int b = 0; b < wb.batch; ++b) {
      std::vector<double> sw(G), sx(G), sy(G);
      for (int n = 0; n < N; ++n) {
        // the normal axis (2) at the window's last frame, magnitude
        const float v = wb.x[((static_cast<std::size_t>(b) * N + n) * wb.length + (wb.length - 1)) * wb.axes + 2];
        const double w = std::max(0.0, std::abs(double(v)) - 1.0);
        const int g = L.group[n];
        sw[g] += w; sx[g] += w * L.coords[n * L.dim]; sy[g] += w * L.coords[n * L.dim + 1];
      }
      for (int g = 0; g < G; ++g) {
        X(b, g * 3) = sw[g];
        X(b, g * 3 + 1) = sw[g] > 0 ? sx[g] / sw[g] : 0;
        X(b, g * 3 + 2) = sw[g] > 0 ? sy[g] / sw[g] : 0;
      }
    }
    return X;
  };
  auto targets = [](const std::vector<float>& v) {
    Eigen::MatrixXd y(v.size() / 3, 3);
    for (Eigen::Index i = 0; i < y.rows(); ++i) for (int a = 0; a < 3; ++a) y(i, a) = v[i * 3 + a];
    return y;
  };
  std::printf("coords dim %d\n", L.dim);
  const double lambdas[] = {1e-3, 1e-2, 1e-1, 1, 10, 100, 1e3, 1e4};
  const RidgeModel m = fit_ridge(centroid_features(*d.train, d.train_tasks), targets(d.train_tasks.pose.value), lambdas, 0.2, 0);
  const Eigen::MatrixXd yt = targets(d.test_tasks.pose.value);
  const Eigen::MatrixXd p = predict(m, centroid_features(*d.test, d.test_tasks));
  const Eigen::RowVectorXd mean = targets(d.train_tasks.pose.value).colwise().mean();
  for (int a = 0; a < 3; ++a) {
    const double r = std::sqrt((p.col(a) - yt.col(a)).squaredNorm() / yt.rows());
    const double r0 = std::sqrt((yt.col(a).array() - mean(a)).square().sum() / yt.rows());
    std::printf("centroid ridge axis %d: rmse %.3f (constant %.3f), lambda %.3g\n", a, r, r0, m.lambda);
  }
  // The sequence head on a random encoder's features: its curves.
  TrainConfig cfg = c.train;
  auto model = make_jepa_model<float>(cfg, d.skin.graph, 3, 0);
  FrozenFeatures<float> ftr(embed_windows(model->target, model->tokenizer, model->encoder, *d.train, d.train_tasks.windows), N, cfg.dim);
  SequenceHeadConfig hc; hc.dim = cfg.dim; hc.heads = 3; hc.length = 10; hc.outputs = 3;
  SequenceModel<float> sm(hc, 1);
  HeadTrainConfig h = c.heads.sequence; h.max_epochs = 40; h.patience = 40;
  const HeadTrainResult r = train_sequence_head(sm, ftr, d.train_tasks.pose, h);
  for (std::size_t e = 0; e < r.train_loss.size(); ++e) std::printf("epoch %zu train %.4f val %.4f\n", e, r.train_loss[e], r.validation_loss[e]);
}
