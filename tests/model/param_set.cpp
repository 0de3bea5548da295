#include <doctest/doctest.h>

#include <tjepa/core/param_set.hpp>

TEST_SUITE("model") {
  TEST_CASE("ParamSet registers named views in one flat aligned buffer") {
    tjepa::ParamSet<float> ps;
    auto w = ps.add("blocks.0.attn.qkv.weight", {576, 192});
    auto b = ps.add("blocks.0.attn.qkv.bias", {576});
    auto n = ps.add("blocks.0.norm1.weight", {192});
    auto pos = ps.add("pos_embed", {1, 368, 192});
    auto mt = ps.add("mask_token", {1, 1, 3});
    CHECK_THROWS_AS(ps.add("pos_embed", {3}), tjepa::ConfigError);
    CHECK_THROWS_AS(ps.add("zero", {0, 3}), tjepa::ShapeError);
    ps.allocate();
    CHECK_THROWS_AS(ps.add("late", {3}), tjepa::ConfigError);
    CHECK(ps.count() == 5);
    CHECK(ps.numel() == 576 * 192 + 576 + 192 + 368 * 192 + 3);
    for (auto id : {w, b, n, pos, mt}) CHECK(reinterpret_cast<std::uintptr_t>(ps.value(id)) % 64 == 0);
    CHECK(ps.id("pos_embed").offset == pos.offset);
    CHECK_THROWS_WITH_AS(ps.id("nope"), "ParamSet: no parameter named 'nope'", tjepa::ConfigError);

    // Decay groups: no decay on biases and 1-D tensors; decay on 2-D and higher.
    auto decay = ps.decay_group();
    auto no_decay = ps.no_decay_group();
    CHECK(decay == std::vector<std::size_t>{w.index, pos.index, mt.index});
    CHECK(no_decay == std::vector<std::size_t>{b.index, n.index});

    ps.grad(b)[3] = 2.0f;
    ps.zero_grad();
    CHECK(ps.grad(b)[3] == 0.0f);

    tjepa::ParamSet<float> other;
    other.add("blocks.0.attn.qkv.weight", {576, 192});
    CHECK_FALSE(ps.same_layout(other));
  }
}
