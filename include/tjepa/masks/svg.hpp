#pragma once
// Pictures of one sample's masks over the layout, with the graph stage's SVG writer: the context
// filled blue, each target filled in its own colour (where targets overlap, the first listed wins)
// and outlined in that colour, so overlaps still show; tokens in neither are light grey.
#include <filesystem>
#include <string>

#include "tjepa/core/error.hpp"
#include "tjepa/graph/colors.hpp"
#include "tjepa/graph/skin.hpp"
#include "tjepa/graph/svg.hpp"
#include "tjepa/masks/collator.hpp"

namespace tjepa {

inline constexpr const char* kMaskContextColor = "#1f77b4";
inline constexpr const char* kMaskNeitherColor = "#e5e5e5";

// Colour of target j (category colours after the context's blue).
inline std::string mask_target_color(int j) { return category_color(j + 1); }

// Drawing options for sample `sample` of a batch over n tokens.
inline SvgOptions mask_svg_options(const MaskBatch& batch, int sample, int n) {
  require<ConfigError>(sample >= 0 && sample < batch.B, "mask_svg_options: sample ", sample,
                       ", expected in [0, ", batch.B, ")");
  SvgOptions o;
  o.fill.assign(n, kMaskNeitherColor);
  for (int v : batch.context_row(sample)) {
    require<ShapeError>(v >= 0 && v < n, "mask_svg_options: context token ", v, ", expected < ", n);
    o.fill[v] = kMaskContextColor;
  }
  for (int j = batch.num_targets() - 1; j >= 0; --j) {
    const TargetSet& ts = batch.targets[j];
    const auto row = ts.row(sample);
    for (int v : row) {
      require<ShapeError>(v >= 0 && v < n, "mask_svg_options: target token ", v, ", expected < ", n);
      o.fill[v] = mask_target_color(j);
    }
    SvgHighlight h;
    h.taxels.assign(row.begin(), row.end());
    h.color = mask_target_color(j);
    h.label = std::string(to_string(ts.kind)) + " target" +
              (ts.part >= 0 ? " (part " + std::to_string(ts.part) + ")" : std::string()) + ", " +
              std::to_string(ts.size) + " tokens";
    o.highlights.insert(o.highlights.begin(), std::move(h));
  }
  return o;
}

// Writes sample `sample` of a batch drawn on skin's graph as an SVG file (atomically).
inline void write_mask_svg(const std::filesystem::path& path, const Skin& skin, const MaskBatch& batch,
                           int sample, const std::string& title = {}) {
  SvgOptions o = mask_svg_options(batch, sample, skin.size());
  o.title = title.empty() ? "context (" + std::to_string(batch.K) + " tokens, blue) and " +
                                std::to_string(batch.num_targets()) + " targets"
                          : title;
  write_svg(path, skin, o);
}

}  // namespace tjepa
