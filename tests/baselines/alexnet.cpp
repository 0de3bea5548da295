// BYOL's AlexNet trunk (baselines/alexnet.hpp): torchvision's names, a layer-by-layer scalar
// reference in PyTorch's flattening order, the gradient of every tensor against central
// differences, determinism and the errors of bad configurations.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include <tjepa/baselines/alexnet.hpp>
#include <tjepa/kernels/conv2d.hpp>
#include <tjepa/model/init.hpp>

#include "../support/gradcheck.hpp"

using namespace tjepa;

namespace {

template <class T>
bool alexnet_bitwise_equal(const std::vector<T>& a, const std::vector<T>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0;
}

// Scalar max-pool and adaptive average pool (no indices) for the layer-by-layer reference.
std::vector<double> cnn_ref_maxpool(const std::vector<double>& x, int B, int H, int C) {
  const int Ho = (H - 3) / 2 + 1;
  std::vector<double> y(std::size_t(B) * Ho * Ho * C);
  for (int b = 0; b < B; ++b)
    for (int i = 0; i < Ho; ++i)
      for (int j = 0; j < Ho; ++j)
        for (int c = 0; c < C; ++c) {
          double m = -std::numeric_limits<double>::infinity();
          for (int u = 0; u < 3; ++u)
            for (int v = 0; v < 3; ++v)
              m = std::max(m, x[((std::size_t(b) * H + 2 * i + u) * H + 2 * j + v) * C + c]);
          y[((std::size_t(b) * Ho + i) * Ho + j) * C + c] = m;
        }
  return y;
}
std::vector<double> cnn_ref_adaptive(const std::vector<double>& x, int B, int H, int C, int R) {
  std::vector<double> y(std::size_t(B) * R * R * C);
  for (int b = 0; b < B; ++b)
    for (int i = 0; i < R; ++i)
      for (int j = 0; j < R; ++j) {
        const int y0 = int(std::floor(double(i) * H / R)), y1 = int(std::ceil(double(i + 1) * H / R));
        const int x0 = int(std::floor(double(j) * H / R)), x1 = int(std::ceil(double(j + 1) * H / R));
        for (int c = 0; c < C; ++c) {
          double s = 0;
          for (int u = y0; u < y1; ++u)
            for (int v = x0; v < x1; ++v) s += x[((std::size_t(b) * H + u) * H + v) * C + c];
          y[((std::size_t(b) * R + i) * R + j) * C + c] = s / double((y1 - y0) * (x1 - x0));
        }
      }
  return y;
}
std::vector<double> cnn_ref_conv_relu(const ParamSet<double>& ps, const AlexNet::Conv& v, const std::vector<double>& x,
                                      int B, int side) {
  const kernels::Conv2dShape s{B, side, side, v.in, v.out, v.k, v.stride, v.pad};
  std::vector<double> y(s.out_size());
  kernels::ref::conv2d_forward(y.data(), x.data(), ps.value(v.weight), ps.value(v.bias), s);
  for (auto& e : y) e = std::max(e, 0.0);
  return y;
}

}  // namespace

TEST_SUITE("baselines") {
  TEST_CASE("AlexNet registers torchvision's names / shapes and PyTorch's Conv2d init") {
    ParamSet<float> ps;
    const AlexNetConfig config;
    const AlexNet net(ps, config, "online.");
    ps.allocate();
    init_params(ps, 5);
    const std::array<std::string, 5> index{"0", "3", "6", "8", "10"};
    const std::array<std::int64_t, 5> in{3, 64, 192, 384, 256}, out{64, 192, 384, 256, 256}, k{11, 5, 3, 3, 3};
    REQUIRE(ps.count() == 10);
    for (std::size_t i = 0; i < 5; ++i) {
      const ParamInfo& w = ps.infos()[2 * i];
      const ParamInfo& b = ps.infos()[2 * i + 1];
      CHECK(w.name == "online.features." + index[i] + ".weight");
      CHECK(b.name == "online.features." + index[i] + ".bias");
      CHECK(w.shape == std::vector<std::int64_t>{out[i], in[i], k[i], k[i]});
      CHECK(b.shape == std::vector<std::int64_t>{out[i]});
      const double bound = 1.0 / std::sqrt(double(in[i] * k[i] * k[i]));
      CHECK(w.init == ParamInit::uniform);
      CHECK(b.init == ParamInit::uniform);
      CHECK(w.bound == doctest::Approx(bound));
      CHECK(b.bound == doctest::Approx(bound));
      CHECK(w.decay);
      CHECK_FALSE(b.decay);
      double most = 0;
      for (float v : ps.value_span(ps.id(2 * i))) most = std::max(most, double(std::abs(v)));
      CHECK(most <= bound);
      CHECK(most > 0.9 * bound);
    }
    CHECK(ps.numel() == 2469696);  // torchvision's alexnet().features
    CHECK(net.out_dim() == 9216);
    const AlexNetSides s = config.sides();
    CHECK(s.conv0 == 55);
    CHECK(s.pool0 == 27);
    CHECK(s.pool1 == 13);
    CHECK(s.pool2 == 6);
    CHECK(AlexNet::flops(config, 2) == 4.0 * 655566528.0);  // 0.66 G multiply-adds per image
  }

  TEST_CASE("AlexNet forward equals the layer-by-layer scalar reference in PyTorch's flattening order") {
    test::SingleThread one;
    AlexNetConfig config;
    config.in_channels = 2;
    config.image_size = 95;
    config.widths = {4, 6, 5, 4, 3};
    config.pooled = 3;
    ParamSet<double> ps;
    const AlexNet net(ps, config);
    ps.allocate();
    init_params(ps, 9);
    const int B = 2, S = config.image_size;
    Rng rng(3);
    const auto x = test::random_vector<double>(std::size_t(B) * S * S * 2, rng);
    std::vector<double> f(std::size_t(B) * net.out_dim());
    AlexNetCache<double> cache;
    net.forward(ps, x.data(), B, f.data(), cache);

    const AlexNetSides s = config.sides();
    REQUIRE(s.pool2 == 2);
    auto h = cnn_ref_conv_relu(ps, net.convs[0], x, B, S);
    h = cnn_ref_maxpool(h, B, s.conv0, 4);
    h = cnn_ref_conv_relu(ps, net.convs[1], h, B, s.pool0);
    h = cnn_ref_maxpool(h, B, s.pool0, 6);
    h = cnn_ref_conv_relu(ps, net.convs[2], h, B, s.pool1);
    h = cnn_ref_conv_relu(ps, net.convs[3], h, B, s.pool1);
    h = cnn_ref_conv_relu(ps, net.convs[4], h, B, s.pool1);
    h = cnn_ref_maxpool(h, B, s.pool1, 3);
    h = cnn_ref_adaptive(h, B, s.pool2, 3, 3);  // [B, 3, 3, 3] NHWC
    for (int b = 0; b < B; ++b)
      for (int c = 0; c < 3; ++c)
        for (int p = 0; p < 9; ++p) {
          INFO("b ", b, " c ", c, " pixel ", p);
          CHECK(f[std::size_t(b) * 27 + std::size_t(c) * 9 + p] ==
                doctest::Approx(h[(std::size_t(b) * 9 + p) * 3 + c]).epsilon(1e-12));
        }
  }

  TEST_CASE("AlexNet gradients of every parameter and the image match central differences (double)") {
    test::SingleThread one;
    struct Case {
      int in_channels, image_size;
      std::array<int, 5> widths;
      int pooled;
    };
    for (const Case& k : {Case{3, 63, {4, 6, 5, 4, 3}, 2}, Case{2, 67, {3, 5, 4, 4, 3}, 6}}) {
      INFO("image_size ", k.image_size, " pooled ", k.pooled);
      AlexNetConfig config;
      config.in_channels = k.in_channels;
      config.image_size = k.image_size;
      config.widths = k.widths;
      config.pooled = k.pooled;
      ParamSet<double> ps;
      const AlexNet net(ps, config);
      ps.allocate();
      init_params(ps, 17);
      const int B = 2, S = config.image_size;
      Rng rng(29);
      auto x = test::random_vector<double>(std::size_t(B) * S * S * std::size_t(k.in_channels), rng);
      const auto r = test::random_vector<double>(std::size_t(B) * net.out_dim(), rng);
      std::vector<double> f(r.size()), dx(x.size(), 0.0);
      AlexNetCache<double> cache, probe;
      auto loss = [&] {
        net.forward(ps, x.data(), B, f.data(), probe);
        return test::dot(f.data(), r.data(), f.size());
      };
      ps.zero_grad();
      net.forward(ps, x.data(), B, f.data(), cache);
      net.backward(ps, r.data(), cache, dx.data());
      test::check_param_gradients(ps, loss);
      CHECK(test::gradient_error(x.data(), dx.data(), x.size(), loss, 96) < test::grad_tolerance);
      // Without the image's gradient the parameters' are the same.
      const std::vector<double> g(ps.grads().begin(), ps.grads().end());
      ps.zero_grad();
      net.backward(ps, r.data(), cache);
      CHECK(test::max_scaled_diff(std::vector<double>(ps.grads().begin(), ps.grads().end()), g) < 1e-14);
    }
  }

  TEST_CASE("AlexNet forward and backward are deterministic (float)") {
    AlexNetConfig config;
    config.image_size = 99;
    config.widths = {16, 24, 20, 16, 12};
    ParamSet<float> ps;
    const AlexNet net(ps, config);
    ps.allocate();
    init_params(ps, 1);
    const int B = 3, S = config.image_size;
    Rng rng(4);
    const auto x = test::random_vector<float>(std::size_t(B) * S * S * 3, rng);
    const auto r = test::random_vector<float>(std::size_t(B) * net.out_dim(), rng);
    std::vector<float> f1(r.size()), f2(r.size()), dx1(x.size(), 0.0f), dx2(x.size(), 0.0f);
    AlexNetCache<float> c1, c2;
    net.forward(ps, x.data(), B, f1.data(), c1);
    net.forward(ps, x.data(), B, f2.data(), c2);
    CHECK(alexnet_bitwise_equal(f1, f2));
    net.forward(ps, x.data(), B, f2.data(), c1);  // a reused cache
    CHECK(alexnet_bitwise_equal(f1, f2));
    ps.zero_grad();
    net.backward(ps, r.data(), c1, dx1.data());
    const std::vector<float> g1(ps.grads().begin(), ps.grads().end());
    ps.zero_grad();
    net.backward(ps, r.data(), c2, dx2.data());
    CHECK(alexnet_bitwise_equal(g1, std::vector<float>(ps.grads().begin(), ps.grads().end())));
    CHECK(alexnet_bitwise_equal(dx1, dx2));
    bool finite = true, nonzero = false;
    for (float v : g1) {
      finite = finite && std::isfinite(v);
      nonzero = nonzero || v != 0.0f;
    }
    CHECK(finite);
    CHECK(nonzero);
  }

  TEST_CASE("AlexNet and conv2d reject bad shapes with messages naming the values") {
    AlexNetConfig small;
    small.image_size = 62;
    CHECK_THROWS_WITH_AS(small.validate(), doctest::Contains("image_size 62"), ConfigError);
    {
      ParamSet<float> ps;
      CHECK_THROWS_WITH_AS(AlexNet(ps, small), doctest::Contains("expected in [63"), ConfigError);
    }
    AlexNetConfig smallest;
    smallest.image_size = 63;
    CHECK_NOTHROW(smallest.validate());
    CHECK(smallest.sides().pool2 == 1);
    AlexNetConfig width;
    width.widths[2] = 0;
    CHECK_THROWS_WITH_AS(width.validate(), doctest::Contains("widths[2] = 0"), ConfigError);
    AlexNetConfig pooled;
    pooled.pooled = 0;
    CHECK_THROWS_WITH_AS(pooled.validate(), doctest::Contains("pooled 0"), ConfigError);
    AlexNetConfig channels;
    channels.in_channels = 0;
    CHECK_THROWS_WITH_AS(channels.validate(), doctest::Contains("in_channels 0"), ConfigError);

    AlexNetConfig tiny;
    tiny.image_size = 63;
    tiny.widths = {2, 2, 2, 2, 2};
    ParamSet<float> ps;
    const AlexNet net(ps, tiny);
    std::vector<float> x(63 * 63 * 3), f(std::size_t(net.out_dim()));
    AlexNetCache<float> cache;
    CHECK_THROWS_WITH_AS(net.forward(ps, x.data(), 1, f.data(), cache), doctest::Contains("not allocated"),
                         ConfigError);
    ps.allocate();
    CHECK_THROWS_WITH_AS(net.forward(ps, x.data(), 0, f.data(), cache), doctest::Contains("B = 0"), ShapeError);
    CHECK_THROWS_WITH_AS(net.backward(ps, f.data(), cache),
                         doctest::Contains("no forward pass"), ConfigError);

    const kernels::Conv2dShape too_small{1, 3, 3, 1, 1, 11, 4, 2};
    CHECK(too_small.Ho() == 0);
    CHECK_THROWS_WITH_AS(too_small.validate(), doctest::Contains("input 3x3 with padding 2 is smaller than the kernel 11"),
                         ShapeError);
    CHECK_THROWS_WITH_AS((kernels::Conv2dShape{1, 8, 8, 1, 1, 3, 0, 1}.validate()), doctest::Contains("stride 0"),
                         ShapeError);
    CHECK_THROWS_WITH_AS((kernels::Conv2dShape{2, 8, 8, 0, 4, 3, 1, 1}.validate()), doctest::Contains("C 0"),
                         ShapeError);
    std::vector<float> in(4), out(1);
    CHECK_THROWS_WITH_AS(kernels::maxpool2d_forward(out.data(), static_cast<std::int32_t*>(nullptr), in.data(), 1, 2,
                                                    2, 1, 3, 2),
                         doctest::Contains("input 2x2 is smaller than the window 3"), ShapeError);
  }
}
