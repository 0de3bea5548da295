// The BYOL baseline: the tactile images (the Allegro hand's canvas against the reference's
// placement, packing, resampling against PyTorch's formulas, the augmentations' properties), the
// projector's BatchNorm MLP and the cosine loss against central differences, the whole BYOL loss
// against central differences for every online parameter on a tiny AlexNet, the update.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Wuninitialized"
#endif
#include <doctest/doctest.h>

#include <tjepa/tjepa.hpp>
// The modules this file tests (the umbrella above holds them all; named here so each is traceable).
#include <tjepa/baselines/taxel_image.hpp>
#include <tjepa/baselines/projection_mlp.hpp>
#include <tjepa/baselines/byol.hpp>

#include <algorithm>
#include <cmath>
#include <functional>
#include <set>
#include <vector>

#include "../support/gradcheck.hpp"

using namespace tjepa;

namespace {

// A tiny BYOL: 63 × 63 images of 2 channels, AlexNet widths 3..4, pooled 2, projection 5.
ByolConfig byol_tiny_config() {
  ByolConfig c;
  c.encoder.in_channels = 2;
  c.encoder.image_size = 63;
  c.encoder.widths = {3, 4, 4, 3, 3};
  c.encoder.pooled = 2;
  c.image = TaxelImageConfig::for_channels(2);
  c.image.image_size = 63;
  c.image.range = 2.0;
  c.projection = 5;
  c.hidden = 6;
  return c;
}

// check_param_gradients, except for tensors the loss does not depend on: a bias just before a
// BatchNorm (the batch mean takes the shift away). There the analytic gradient is ~0 and
// central differences must be ~0 too, in absolute terms.
void byol_check_gradients(ParamSet<double>& ps, const std::function<double()>& loss) {
  for (std::size_t i = 0; i < ps.count(); ++i) {
    const ParamId id = ps.id(i);
    INFO("parameter ", ps.infos()[i].name);
    double norm = 0;
    for (double g : ps.grad_span(id)) norm += g * g;
    if (std::sqrt(norm) > 1e-10) {
      CHECK(test::gradient_error(ps.value(id), ps.grad(id), id.size, loss) < test::grad_tolerance);
      continue;
    }
    for (std::size_t k = 0; k < id.size; k += std::max<std::size_t>(1, id.size / 4)) {
      double* x = ps.value(id) + k;
      const double x0 = *x, h = 1e-5;
      *x = x0 + h;
      const double lp = loss();
      *x = x0 - h;
      const double lm = loss();
      *x = x0;
      CHECK(std::abs(lp - lm) / (2 * h) < 1e-8);
    }
  }
}

}  // namespace

TEST_SUITE("baselines") {
  TEST_CASE("T-DEX canvas of the Allegro hand: the reference's placement of each pad and fingertip cell") {
    const Skin skin = layouts::allegro_xela();
    const TaxelCanvas c = TaxelCanvas::tdex_allegro(skin.layout);
    CHECK(c.height == 26);
    CHECK(c.width == 24);
    CHECK(std::set<int>(c.pixel.begin(), c.pixel.end()).size() == 368);
    // The reference's xela_flat_to_grid: a fingertip's taxel k (its own numbering) sits at
    // grid[0, 2 + k] (k < 2), grid[1, 1 + k − 2] (k < 6), grid[2 + (k − 6) / 6, (k − 6) % 6];
    // XELA_IMG_ORDER puts the tips at [4, 0], [0, 6], [0, 12], [0, 18]. reference_columns()
    // gives each tjepa taxel's number in the reference's order.
    const std::vector<int> ref = layouts::allegro::reference_columns();
    const int tips[4][3] = {{0, 4, 0}, {62, 0, 6}, {140, 0, 12}, {218, 0, 18}};
    for (const auto& t : tips)
      for (int j = t[0]; j < t[0] + 30; ++j) {
        const int k = ref[std::size_t(j)] - t[0];
        const int gy = k < 2 ? 0 : k < 6 ? 1 : 2 + (k - 6) / 6;
        const int gx = k < 2 ? 2 + k : k < 6 ? 1 + (k - 2) : (k - 6) % 6;
        CHECK(c.pixel[std::size_t(j)] == (t[1] + gy) * 24 + t[2] + gx);
      }
    // A phalanx pad's 4 × 4 two columns into its slot (link_15 = thumb_1 at [10, 0]), a palm pad's
    // 4 × 6 (ahr_palm_3 = palm_2 at [22, 12]).
    CHECK(c.pixel[30] == 10 * 24 + 2);
    CHECK(c.pixel[30 + 15] == 13 * 24 + 5);
    CHECK(c.pixel[367] == 25 * 24 + 17);
    CHECK(TaxelCanvas::from_layout(skin.layout).pixel == c.pixel);
    CHECK_THROWS_WITH_AS(TaxelCanvas::tdex_allegro(layouts::grid_skin({}).layout),
                         doctest::Contains("expected the Allegro hand's 368"), ConfigError);
  }

  TEST_CASE("canvas of any skin: pads packed by their cells / 2-D coordinates on the taxel pitch") {
    layouts::GridSkinOptions o;
    o.rows = 4, o.cols = 6, o.group_rows = 2, o.group_cols = 3;
    const Skin grid = layouts::grid_skin(o);
    const TaxelCanvas sheet = TaxelCanvas::from_cells(grid.layout);  // one grid for the part: kept
    CHECK(sheet.height == 4);
    CHECK(sheet.width == 6);
    for (int n = 0; n < 24; ++n)
      CHECK(sheet.pixel[std::size_t(n)] == grid.layout.row[std::size_t(n)] * 6 + grid.layout.col[std::size_t(n)]);
    // The hand's pads each have their own grid: 18 pictures packed in rows.
    const TaxelCanvas pads = TaxelCanvas::from_cells(layouts::allegro_xela().layout);
    pads.validate(368);
    CHECK(pads.height * pads.width < 2 * (4 * 36 + 11 * 16 + 3 * 24));
    // Coordinates: a jittered 5 × 4 sheet without its top-right taxel, and one more taxel 0.9 mm
    // from the first: it moves to the nearest free pixel.
    TaxelLayout l;
    l.dim = 2;
    for (int y = 0; y < 4; ++y)
      for (int x = 0; x < 5; ++x)
        if (x < 4 || y < 3) l.coords.insert(l.coords.end(), {x * 4.0 + 0.3 * ((x + y) % 2), y * 4.0});
    l.coords.insert(l.coords.end(), {12.6, 10.0});
    l.part.assign(20, 0), l.group.assign(20, 0), l.part_names = {"sheet"}, l.group_names = {"sheet"}, l.group_part = {0};
    const TaxelCanvas xy = TaxelCanvas::from_coordinates(l);
    xy.validate(20);
    CHECK(xy.width == 5);
    CHECK(xy.height == 4);
    CHECK(xy.pixel[0] == 3 * xy.width + 0);  // (0, 0) mm: the bottom row, image rows go down
    CHECK(xy.pixel[18] == 0 * xy.width + 3);
    CHECK(xy.pixel[19] == 0 * xy.width + 4);  // (12.6, 10) rounds to (3, 0), taken: the free (4, 0)
    // A crowded corner: the grid is refined until every taxel has its own pixel.
    l.coords.insert(l.coords.end(), {0.9, 0.0, 0.0, 0.8, 0.7, 0.7});
    l.part.assign(23, 0), l.group.assign(23, 0);
    const TaxelCanvas fine = TaxelCanvas::from_coordinates(l);
    fine.validate(23);
    CHECK(fine.width > 5);
    l.dim = 3;
    CHECK_THROWS_WITH_AS(TaxelCanvas::from_coordinates(l), doctest::Contains("expected 2-D"), ConfigError);
  }

  TEST_CASE("resampling as PyTorch's antialiased bilinear: upsampling / 4 to 2 / identity") {
    // Upsampling 2 → 4 (align_corners = False): outputs at input coordinates −0.25, 0.25, 0.75, 1.25.
    const ResampleAxis up(0, 2, 2, 4);
    const float in[2] = {1.f, 3.f};
    std::vector<float> out(4), tmp;
    const ResampleAxis one(0, 1, 1, 1);
    resample_image(out.data(), in, 2, 1, one, up, tmp);
    CHECK(out[0] == doctest::Approx(1.0));
    CHECK(out[1] == doctest::Approx(1.5));
    CHECK(out[2] == doctest::Approx(2.5));
    CHECK(out[3] == doctest::Approx(3.0));
    // Downsampling 4 → 2 with the antialias triangle of width 2: weights 3/7, 3/7, 1/7 for output 0.
    const ResampleAxis down(0, 4, 4, 2);
    const float v[4] = {7.f, 0.f, 0.f, 0.f};
    std::vector<float> o2(2);
    resample_image(o2.data(), v, 4, 1, one, down, tmp);
    CHECK(o2[0] == doctest::Approx(3.0));
    CHECK(o2[1] == doctest::Approx(0.0));
    const ResampleAxis same(0, 5, 5, 5);
    const float w[5] = {1, -2, 3, 4, 5};
    std::vector<float> o3(5);
    resample_image(o3.data(), w, 5, 1, one, same, tmp);
    for (int i = 0; i < 5; ++i) CHECK(o3[std::size_t(i)] == doctest::Approx(w[i]));
  }

  TEST_CASE("T-DEX augmentations: crops inside the image at the drawn scale / blur keeps a constant image") {
    Rng rng(3);
    for (int i = 0; i < 200; ++i) {
      const CropBox b = random_resized_crop(rng, 224, 224, {0.9, 1.0}, {3.0 / 4.0, 4.0 / 3.0});
      CHECK(b.top >= 0);
      CHECK(b.left >= 0);
      CHECK(b.top + b.height <= 224);
      CHECK(b.left + b.width <= 224);
      const double share = double(b.height) * b.width / (224.0 * 224.0);
      CHECK(share >= 0.88);
      CHECK(share <= 1.0);
    }
    std::vector<float> img(5 * 4 * 2, 0.7f), tmp;
    gaussian_blur3(img.data(), 5, 4, 2, 1.5, tmp);
    for (float v : img) CHECK(v == doctest::Approx(0.7f));
    // An impulse spreads with torchvision's kernel: σ = 1 gives 0.4519 in the centre.
    std::vector<float> dot(25, 0.f);
    dot[12] = 1.f;
    gaussian_blur3(dot.data(), 5, 5, 1, 1.0, tmp);
    const double e = std::exp(-0.5), k0 = 1 / (1 + 2 * e), k1 = e / (1 + 2 * e);
    CHECK(dot[12] == doctest::Approx(k0 * k0));
    CHECK(dot[7] == doctest::Approx(k0 * k1));
    CHECK(dot[6] == doctest::Approx(k1 * k1));
    CHECK(dot[0] == 0.f);
    // Reflect padding at the border: an impulse in the corner counts its mirror images.
    std::vector<float> corner(9, 0.f);
    corner[0] = 1.f;
    gaussian_blur3(corner.data(), 3, 3, 1, 1.0, tmp);
    CHECK(corner[0] == doctest::Approx(k0 * k0));
    CHECK(corner[4] == doctest::Approx(k1 * k1));
  }

  TEST_CASE("TaxelImager: a frame becomes a clamped and normalized image / augmentation is a function of the stream") {
    TaxelCanvas c{2, 2, {0, 1, 2, 3}};
    TaxelImageConfig ic = TaxelImageConfig::for_channels(1);
    ic.image_size = 2;
    ic.range = 2.0;
    TaxelImager im(c, 1, ic);
    const float frame[4] = {-5.f, 0.f, 1.f, 2.f};
    float out[4];
    im.image(out, frame, 1, 1, nullptr);
    const double expect[4] = {0.0, 0.5, 0.75, 1.0};
    for (int i = 0; i < 4; ++i) CHECK(out[i] == doctest::Approx((expect[i] - 0.449) / 0.226));
    ic.image_size = 16;
    TaxelImager big(c, 1, ic);
    std::vector<float> a(256), b(256), d(256);
    Rng r1(9, 1), r2(9, 1);
    big.image(a.data(), frame, 1, 1, &r1);
    big.image(b.data(), frame, 1, 1, &r2);
    CHECK(a == b);
    bool differs = false;
    for (int s = 2; s < 12 && !differs; ++s) {
      Rng r(9, std::uint64_t(s));
      big.image(d.data(), frame, 1, 1, &r);
      differs = d != a;
    }
    CHECK(differs);
    CHECK_THROWS_WITH_AS(TaxelImager(c, 2, TaxelImageConfig{}), doctest::Contains("3 normalization values for 2 channels"),
                         ConfigError);
    // One mean for both channels, a std per channel.
    TaxelImageConfig two = TaxelImageConfig::for_channels(2);
    two.image_size = 2, two.range = 2.0, two.mean = {0.5}, two.std = {0.25, 0.5};
    TaxelImager im2(c, 2, two);
    const float frame2[8] = {2.f, 2.f, 0.f, 0.f, -2.f, -2.f, 0.f, 0.f};  // taxel-major: 4 taxels × 2 axes
    float out2[8];
    im2.image(out2, frame2, 2, 1, nullptr);
    CHECK(out2[0] == doctest::Approx(2.0));   // (1 − 0.5) / 0.25
    CHECK(out2[1] == doctest::Approx(1.0));   // (1 − 0.5) / 0.5
    CHECK(out2[4] == doctest::Approx(-2.0));  // (0 − 0.5) / 0.25
    CHECK(out2[5] == doctest::Approx(-1.0));
  }

  TEST_CASE("ProjectionMlp: BatchNorm over the batch / gradients of input and parameters") {
    const test::SingleThread one_thread;
    ParamSet<double> ps;
    ProjectionMlp mlp(ps, ProjectionMlpConfig{5, 7, 3, 1e-5});
    ps.allocate();
    init_params(ps, 2);
    CHECK(ps.contains("net.0.weight"));
    CHECK(ps.contains("net.1.weight"));
    CHECK(ps.contains("net.3.bias"));
    for (double v : ps.value_span(mlp.fc0.weight)) CHECK(std::abs(v) <= 1 / std::sqrt(5.0));
    test::randomize(ps, 3);
    const int M = 4;
    Rng rng(4);
    auto x = test::normal_vector(std::size_t(M) * 5, rng);
    auto w = test::normal_vector(std::size_t(M) * 3, rng);
    std::vector<double> out(w.size());
    ProjectionMlpCache<double> cache;
    auto loss = [&] {
      ProjectionMlpCache<double> c;
      mlp.forward(ps, x.data(), M, out.data(), c);
      return test::dot(w.data(), out.data(), out.size());
    };
    ps.zero_grad();
    mlp.forward(ps, x.data(), M, out.data(), cache);
    std::vector<double> dx(x.size(), 0.0);
    mlp.backward(ps, w.data(), x.data(), dx.data(), cache);
    CHECK(test::gradient_error(x.data(), dx.data(), x.size(), loss) < test::grad_tolerance);
    byol_check_gradients(ps, loss);
    // Batch statistics: shifting every input row by the same vector changes nothing after net.0.
    const double l = loss();
    std::vector<double> shift(5);
    for (int k = 0; k < 5; ++k) shift[std::size_t(k)] = 0.1 * k;
    for (int i = 0; i < M; ++i)
      for (int k = 0; k < 5; ++k) x[std::size_t(i) * 5 + std::size_t(k)] += shift[std::size_t(k)];
    CHECK(loss() == doctest::Approx(l).epsilon(1e-9));
    CHECK_THROWS_WITH_AS(mlp.forward(ps, x.data(), 1, out.data(), cache), doctest::Contains("expected >= 2 rows"),
                         ShapeError);
  }

  TEST_CASE("BYOL cosine loss: 2 - 2 cos / central differences") {
    Rng rng(5);
    const int M = 3, P = 4;
    auto p = test::normal_vector(std::size_t(M) * P, rng);
    auto z = test::normal_vector(std::size_t(M) * P, rng);
    std::vector<double> dp(p.size(), 0.0);
    const double l = byol_cosine_loss(p.data(), z.data(), M, P, 0.5, dp.data());
    auto f = [&] { return byol_cosine_loss(p.data(), z.data(), M, P, 0.5, static_cast<double*>(nullptr)); };
    CHECK(l == f());
    CHECK(test::gradient_error(p.data(), dp.data(), p.size(), f) < test::grad_tolerance);
    CHECK(byol_cosine_loss(z.data(), z.data(), M, P, 1.0, static_cast<double*>(nullptr)) == doctest::Approx(0.0));
    std::vector<double> neg(z);
    for (double& v : neg) v = -2 * v;
    CHECK(byol_cosine_loss(neg.data(), z.data(), M, P, 1.0, static_cast<double*>(nullptr)) == doctest::Approx(4.0 * M));
  }

  TEST_CASE("BYOL loss: analytic gradient of every online parameter = central differences") {
    const test::SingleThread one_thread;
    const ByolConfig c = byol_tiny_config();
    ByolModel<double> model(c, 1);
    CHECK(std::ranges::equal(model.target.values(), model.online.values()));
    test::randomize(model.target, 4, 0.2);
    test::randomize(model.target_projector, 5);
    test::randomize(model.projector_params, 6);
    test::randomize(model.predictor_params, 7);
    const int B = 3;
    Rng rng(8);
    const auto images = test::normal_vector(std::size_t(2) * B * 63 * 63 * 2, rng);
    ByolWorkspace<double> w;
    auto loss = [&] {
      ByolWorkspace<double> scratch;
      return byol_forward(model, images.data(), B, scratch);
    };
    for (const auto& part : model.trainable()) part.params->zero_grad();
    const double l = byol_forward(model, images.data(), B, w);
    CHECK(l == loss());
    CHECK(l > 0);
    CHECK(l < 8);
    byol_backward(model, w);
    byol_check_gradients(model.online, loss);
    byol_check_gradients(model.projector_params, loss);
    byol_check_gradients(model.predictor_params, loss);
    const double* dbias = model.projector_params.grad(model.projector.fc0.bias);
    CHECK(std::abs(dbias[0]) < 1e-10);  // net.0.bias: BatchNorm takes the shift away
    for (double g : model.target.grads()) CHECK(g == 0.0);
    CHECK_THROWS_WITH_AS(byol_backward(model, w), doctest::Contains("holds no forward pass"), ConfigError);
    CHECK_THROWS_WITH_AS(byol_forward(model, images.data(), 1, w), doctest::Contains("expected >= 2"), ShapeError);
  }

  TEST_CASE("a BYOL update: AdamW on the online network / EMA target of encoder and projector") {
    ByolConfig c = byol_tiny_config();
    c.momentum = 0.9;
    ByolModel<double> model(c, 1);
    CHECK(model.parts().size() == 5);
    CHECK(model.online.contains("features.0.weight"));
    CHECK(model.online.contains("features.10.bias"));
    const int B = 2;
    Rng rng(2);
    const auto images = test::normal_vector(std::size_t(2) * B * 63 * 63 * 2, rng);
    TrainConfig tc;
    tc.schedule.steps = 10, tc.schedule.warmup_steps = 2, tc.batch = B;
    AdamW<double> opt(model.trainable(), tc.adamw);
    const TrainingSchedule sch = tc.schedule.build();
    ByolWorkspace<double> w;
    for (const auto& part : model.trainable()) part.params->zero_grad();
    const double l = byol_forward(model, images.data(), B, w);
    byol_backward(model, w);
    const std::vector<double> target0(model.target.values().begin(), model.target.values().end());
    const std::vector<double> online0(model.online.values().begin(), model.online.values().end());
    const ByolStepStats st = byol_update(model, opt, sch, 3, l);
    CHECK(st.momentum == 0.9);
    CHECK(st.loss == l);
    CHECK(!std::ranges::equal(model.online.values(), online0));
    for (std::size_t i = 0; i < target0.size(); i += 97)
      CHECK(model.target.values()[i] == doctest::Approx(0.9 * target0[i] + 0.1 * model.online.values()[i]));
    c.encoder.image_size = 62;
    c.image.image_size = 62;
    CHECK_THROWS_AS(ByolModel<double>(c, 1), ConfigError);
    c.encoder.image_size = 63;
    CHECK_THROWS_WITH_AS(ByolModel<double>(c, 1), doctest::Contains("expected equal"), ConfigError);
  }
}
