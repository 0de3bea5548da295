// The collator on every built-in layout, over many seeds: the documented properties (check_batch),
// every token a local and a global target with positive frequency, the I-JEPA blocks on the hand,
// and the README picture docs/masks_allegro.svg.
#include <doctest/doctest.h>

#include <tjepa/tjepa.hpp>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <set>
#include <string>
#include <vector>

#include "../support/files.hpp"
#include "check_masks.hpp"

using namespace masks_test;

namespace {

struct NamedSkin {
  std::string name;
  tjepa::Skin skin;
};

std::vector<NamedSkin> builtin_skins() {
  std::vector<NamedSkin> v;
  v.push_back({"allegro_xela", tjepa::layouts::allegro_xela()});
  v.push_back({"grid_skin", tjepa::layouts::grid_skin()});
  v.push_back({"two_part_skin", tjepa::layouts::two_part_skin()});
  v.push_back({"inspire_hand_left", tjepa::layouts::inspire_hand(tjepa::layouts::inspire::Side::left)});
  v.push_back({"inspire_hands", tjepa::layouts::inspire_hands()});
  return v;
}

// Runs `batches` batches of B samples and checks every property; returns per-token counts of
// local and global target membership.
void check_many(const tjepa::MaskCollator& col, int batches, int B, std::uint64_t seed) {
  const int n = col.num_tokens();
  std::vector<int> local(n, 0), global(n, 0);
  bool has_local = false, has_global = false;
  for (int s = 0; s < batches; ++s) {
    const auto b = col.sample(B, seed, static_cast<std::uint64_t>(s));
    check_batch(col, b, B, col.batch_sizes(seed, static_cast<std::uint64_t>(s)));
    for (const auto& ts : b.targets) {
      const bool is_local = ts.kind == tjepa::TargetKind::local;
      (is_local ? has_local : has_global) = true;
      for (int v : ts.indices) ++(is_local ? local : global)[v];
    }
  }
  int never_local = 0, never_global = 0;
  for (int v = 0; v < n; ++v) {
    never_local += has_local && local[v] == 0;
    never_global += has_global && global[v] == 0;
  }
  CHECK(never_local == 0);
  CHECK(never_global == 0);
}

}  // namespace

TEST_SUITE("masks") {
  TEST_CASE("collator properties on every built-in layout with the default configuration") {
    for (const auto& [name, skin] : builtin_skins()) {
      CAPTURE(name);
      tjepa::MaskCollator col(skin.graph, one_thread());
      CHECK(col.per_part() == (skin.graph.num_parts() >= 2));
      check_many(col, 60, 32, 2026);
    }
  }

  TEST_CASE("Allegro: every global target covers all 18 pads and sizes stay in range") {
    const auto skin = tjepa::layouts::allegro_xela();
    REQUIRE(skin.graph.num_nodes() == 368);
    tjepa::MaskCollator col(skin.graph, one_thread());
    CHECK(col.min_context() == 56);  // max(32, ceil(0.15 * 368))
    for (std::uint64_t s = 0; s < 20; ++s) {
      const auto b = col.sample(16, 7, s);
      for (const auto& ts : b.targets) {
        CHECK(ts.size >= 36);  // floor(368 * 0.10)
        CHECK(ts.size <= 66);  // floor(368 * 0.18)
        if (ts.kind != tjepa::TargetKind::global) continue;
        for (int i = 0; i < b.B; ++i) {
          std::vector<char> seen(18, 0);
          for (int v : ts.row(i)) seen[skin.graph.group(v)] = 1;
          CHECK(std::count(seen.begin(), seen.end(), 1) == 18);
        }
      }
    }
  }

  TEST_CASE("ablations on the built-in layouts: 4L and 4G and local context and uniform global") {
    for (const auto& [name, skin] : builtin_skins()) {
      CAPTURE(name);
      for (int variant = 0; variant < 4; ++variant) {
        CAPTURE(variant);
        auto cfg = one_thread();
        cfg.part_targets = tjepa::PartTargets::whole;
        if (variant == 0) cfg.num_local = 4, cfg.num_global = 0;
        if (variant == 1) cfg.num_local = 0, cfg.num_global = 4;
        if (variant == 2) cfg.context_sampling = tjepa::ContextSampling::local;
        if (variant == 3) cfg.global_sampling = tjepa::GlobalSampling::uniform;
        // Whole-sensor local targets of t = floor(N * s) tokens may not fit in one part: the
        // collator refuses such a configuration up front.
        const auto pieces = tjepa::part_pieces(skin.graph);
        const int largest = *std::max_element(pieces.size.begin(), pieces.size.end());
        const bool fits = largest >= static_cast<int>(skin.graph.num_nodes() * cfg.target_ratio.hi);
        if (cfg.num_local > 0 && !fits) {
          CHECK_THROWS_AS(tjepa::MaskCollator(skin.graph, cfg), tjepa::ConfigError);
          continue;
        }
        tjepa::MaskCollator col(skin.graph, cfg);
        check_many(col, 40, 16, 31);
      }
    }
  }

  TEST_CASE("the grouped two-hand graph (DECO-50 with 528 tokens): per-hand targets cover every region") {
    const auto hands = tjepa::layouts::inspire_hands();
    const auto grouping = tjepa::layouts::deco50_grouping(hands);
    const tjepa::TaxelGraph& g = grouping.graph;
    REQUIRE(g.num_nodes() == 528);
    REQUIRE(g.num_parts() == 2);
    tjepa::MaskCollator col(g, one_thread());
    REQUIRE(col.per_part());
    CHECK(col.min_context() == 80);  // max(32, ceil(0.15 * 528))
    check_many(col, 60, 32, 4242);
    for (std::uint64_t s = 0; s < 20; ++s) {
      const auto b = col.sample(16, 5, s);
      REQUIRE(b.num_targets() == 4);
      for (int j = 0; j < 4; ++j) {
        const auto& ts = b.targets[j];
        CHECK(ts.part == j / 2);
        CHECK(ts.kind == (j % 2 == 0 ? tjepa::TargetKind::local : tjepa::TargetKind::global));
        CHECK(ts.size >= 26);  // floor(264 * 0.10)
        CHECK(ts.size <= 47);  // floor(264 * 0.18)
        if (ts.kind != tjepa::TargetKind::global) continue;
        const int regions = col.domain(ts.part).num_groups();
        CHECK(regions == 17);
        for (int i = 0; i < b.B; ++i) {
          std::set<int> seen;
          for (int v : ts.row(i)) seen.insert(g.group(v));
          CHECK(static_cast<int>(seen.size()) == regions);
        }
      }
    }
    // The picture paints each token's taxels.
    const auto b = col.sample(1, 9, 0);
    const auto o = tjepa::mask_svg_options(b, 0, hands.size(), &grouping);
    for (int v : b.context_row(0))
      for (int i : grouping.members_of(v)) CHECK(o.fill[i] == tjepa::kMaskContextColor);
    CHECK(o.highlights[1].taxels.size() >= 4 * static_cast<std::size_t>(b.targets[1].size));
  }

  TEST_CASE("I-JEPA blocks on the Allegro atlas reach the last row and column") {
    const auto skin = tjepa::layouts::allegro_xela();
    const auto grid = tjepa::GridPlacement::from_layout(skin.layout, tjepa::layouts::allegro::kPhalanxPitch);
    auto cfg = one_thread();
    cfg.scheme = tjepa::TargetScheme::ijepa_blocks;
    cfg.min_context_tokens = 16;
    cfg.min_context_ratio = 0.0;
    tjepa::MaskCollator col(skin.graph, cfg, grid);
    bool last_row = false, last_col = false;
    for (std::uint64_t s = 0; s < 200 && !(last_row && last_col); ++s) {
      const auto b = col.sample(8, 13, s);
      check_batch(col, b, 8, col.batch_sizes(13, s));
      for (const auto& ts : b.targets)
        for (int v : ts.indices) {
          last_row |= grid.row[v] == grid.rows - 1;
          last_col |= grid.col[v] == grid.cols - 1;
        }
    }
    CHECK(last_row);
    CHECK(last_col);
  }

  TEST_CASE("mask pictures: every context and target token gets its colour") {
    const auto skin = tjepa::layouts::allegro_xela();
    tjepa::MaskCollator col(skin.graph, one_thread());
    const auto b = col.sample(2, 3, 0);
    const auto o = tjepa::mask_svg_options(b, 1, skin.size());
    for (int v : b.context_row(1)) CHECK(o.fill[v] == tjepa::kMaskContextColor);
    for (int v : b.targets[0].row(1)) CHECK(o.fill[v] == tjepa::mask_target_color(0));
    REQUIRE(o.highlights.size() == 4);
    CHECK(o.highlights[2].taxels == std::vector<int>(b.targets[2].row(1).begin(), b.targets[2].row(1).end()));
    CHECK(o.highlights[0].label.find("local target") == 0);
    CHECK_THROWS_AS(tjepa::mask_svg_options(b, 2, skin.size()), tjepa::ConfigError);
  }

  TEST_CASE("docs/masks_allegro.svg is the library's current drawing of one sample's masks") {
    // TJEPA_UPDATE_DOCS=1 rewrites the committed picture; otherwise it must match.
    const std::filesystem::path doc = std::filesystem::path(TJEPA_SOURCE_DIR) / "docs" / "masks_allegro.svg";
    const auto skin = tjepa::layouts::allegro_xela();
    tjepa::MaskCollator col(skin.graph, one_thread());
    const auto b = col.sample(1, 2026, 0);
    tjepa::SvgOptions o = tjepa::mask_svg_options(b, 0, skin.size());
    o.title = "One sample on the Allegro hand: context " + std::to_string(b.K) +
              " tokens (blue), 2 local + 2 global targets of " + std::to_string(b.targets[0].size) +
              " tokens";
    const std::string svg = tjepa::svg_string(skin, o);
    if (std::getenv("TJEPA_UPDATE_DOCS")) {
      std::filesystem::create_directories(doc.parent_path());
      tjepa::write_svg(doc, skin, o);
    }
    CHECK(tjepa_test::read_file(doc) == svg);
  }
}
