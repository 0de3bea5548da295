#pragma once
// Pictures of one sample's masks over the layout, with the graph stage's SVG writer: the context
// filled blue, each target filled in its own colour (where targets overlap, the first listed wins)
// and outlined in that colour, so overlaps still show; tokens in neither are light grey.
#include <filesystem>
#include <string>

#include "tjepa/core/error.hpp"
#include "tjepa/graph/colors.hpp"
#include "tjepa/graph/grouping.hpp"
#include "tjepa/graph/skin.hpp"
#include "tjepa/graph/svg.hpp"
#include "tjepa/masks/collator.hpp"

namespace tjepa {

inline constexpr const char* kMaskContextColor = "#1f77b4";
inline constexpr const char* kMaskNeitherColor = "#e5e5e5";

// Colour of target j (category colours after the context's blue).
inline std::string mask_target_color(int j) { return category_color(j + 1); }

// Drawing options for sample `sample` of a batch over n tokens. With a grouping, the batch's
// tokens are its group tokens and each paints all its member taxels (n = the number of taxels).
inline SvgOptions mask_svg_options(const MaskBatch& batch, int sample, int n,
                                   const Grouping* grouping = nullptr) {
  require<ConfigError>(sample >= 0 && sample < batch.B, "mask_svg_options: sample ", sample,
                       ", expected in [0, ", batch.B, ")");
  require<ShapeError>(grouping == nullptr || grouping->num_taxels == n, "mask_svg_options: the grouping has ",
                      grouping ? grouping->num_taxels : 0, " taxels, expected ", n);
  const int tokens = grouping ? grouping->num_groups() : n;
  // Paints the taxels of token v.
  const auto each_taxel = [&](int v, auto&& paint) {
    require<ShapeError>(v >= 0 && v < tokens, "mask_svg_options: token ", v, ", expected < ", tokens);
    if (grouping) {
      for (int i : grouping->members_of(v)) paint(i);
    } else {
      paint(v);
    }
  };
  SvgOptions o;
  o.fill.assign(n, kMaskNeitherColor);
  for (int v : batch.context_row(sample)) each_taxel(v, [&](int i) { o.fill[i] = kMaskContextColor; });
  for (int j = batch.num_targets() - 1; j >= 0; --j) {
    const TargetSet& ts = batch.targets[j];
    SvgHighlight h;
    for (int v : ts.row(sample))
      each_taxel(v, [&](int i) {
        o.fill[i] = mask_target_color(j);
        h.taxels.push_back(i);
      });
    h.color = mask_target_color(j);
    h.label = std::string(to_string(ts.kind)) + " target" +
              (ts.part >= 0 ? " (part " + std::to_string(ts.part) + ")" : std::string()) + ", " +
              std::to_string(ts.size) + " tokens";
    o.highlights.insert(o.highlights.begin(), std::move(h));
  }
  return o;
}

// Writes sample `sample` of a batch, drawn on skin's graph (or on a grouping of skin's taxels),
// as an SVG file (atomically).
inline void write_mask_svg(const std::filesystem::path& path, const Skin& skin, const MaskBatch& batch,
                           int sample, const Grouping* grouping = nullptr, const std::string& title = {}) {
  SvgOptions o = mask_svg_options(batch, sample, skin.size(), grouping);
  o.title = title.empty() ? "context (" + std::to_string(batch.K) + " tokens, blue) and " +
                                std::to_string(batch.num_targets()) + " targets"
                          : title;
  write_svg(path, skin, o);
}

}  // namespace tjepa
