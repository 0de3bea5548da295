#pragma once
// I-JEPA multi-block masks on a grid placement of the tokens (the "4I-JEPA" ablation).
//
// Each token sits in a cell (row, col) of a rows × cols grid; cells may be empty (a hand's atlas
// has gaps) or, on a coarse grid, hold several tokens. A block is an h × w rectangle of cells and
// holds the tokens of its cells.
//
// Block shape, per batch (I-JEPA's _sample_block_size): area = scale·rows·cols with
// scale ~ U(scale range) — times N/(rows·cols) occupancy, i.e. area = scale·N/occupancy, so that
// a block holds about scale·N tokens on a sparse atlas too; aspect ~ U(aspect range);
// h = round(sqrt(area·aspect)), w = round(sqrt(area/aspect)), clamped to [1, rows] × [1, cols].
// Scale and aspect are two independent draws (I-JEPA reuses one uniform for both).
// Block position, per sample: top ~ U{0, .., rows - h}, left ~ U{0, .., cols - w}.
// I-JEPA's off-by-one is fixed: it clamps h to rows - 1 and draws top in [0, rows - h), so its
// blocks never touch the last row or column.
#include <algorithm>
#include <cmath>
#include <span>
#include <utility>
#include <vector>

#include "tjepa/core/error.hpp"
#include "tjepa/core/random.hpp"
#include "tjepa/masks/config.hpp"
#include "tjepa/layout/taxel_layout.hpp"
#include "tjepa/masks/workspace.hpp"

namespace tjepa {

struct GridPlacement {
  int rows = 0;
  int cols = 0;
  std::vector<int> row;  // [N] in [0, rows)
  std::vector<int> col;  // [N] in [0, cols)

  int size() const { return static_cast<int>(row.size()); }

  void validate(int n) const {
    require<ConfigError>(rows >= 1 && cols >= 1, "GridPlacement: grid ", rows, " x ", cols,
                         ", expected at least 1 x 1");
    require<ShapeError>(size() == n && static_cast<int>(col.size()) == n, "GridPlacement: row/col have ",
                        row.size(), "/", col.size(), " entries, expected one per token (", n, ")");
    for (int i = 0; i < n; ++i)
      require<DataError>(row[i] >= 0 && row[i] < rows && col[i] >= 0 && col[i] < cols,
                         "GridPlacement: token ", i, " in cell (", row[i], ", ", col[i],
                         "), expected inside the ", rows, " x ", cols, " grid");
  }

  // Places 2-D points ([N, 2] row-major, x then y) on a grid of the given pitch (same unit):
  // col = round((x - min x)/pitch), row = round((max y - y)/pitch), so row 0 is the top.
  static GridPlacement from_points(std::span<const double> xy, double pitch) {
    require<ShapeError>(!xy.empty() && xy.size() % 2 == 0, "GridPlacement::from_points: ", xy.size(),
                        " values, expected N x 2 with N >= 1");
    require<ConfigError>(pitch > 0 && std::isfinite(pitch), "GridPlacement::from_points: pitch ",
                         pitch, ", expected > 0");
    const int n = static_cast<int>(xy.size() / 2);
    double xmin = xy[0], ymax = xy[1];
    for (int i = 0; i < n; ++i) {
      xmin = std::min(xmin, xy[2 * i]);
      ymax = std::max(ymax, xy[2 * i + 1]);
    }
    GridPlacement gp;
    gp.row.resize(n);
    gp.col.resize(n);
    for (int i = 0; i < n; ++i) {
      gp.col[i] = static_cast<int>(std::lround((xy[2 * i] - xmin) / pitch));
      gp.row[i] = static_cast<int>(std::lround((ymax - xy[2 * i + 1]) / pitch));
      gp.rows = std::max(gp.rows, gp.row[i] + 1);
      gp.cols = std::max(gp.cols, gp.col[i] + 1);
    }
    return gp;
  }

  // The layout's taxels on a grid of the given pitch (mm), from their x-y coordinates.
  static GridPlacement from_layout(const TaxelLayout& layout, double pitch_mm) {
    require<ConfigError>(layout.has_coords(), "GridPlacement::from_layout: the layout has no coordinates");
    std::vector<double> xy(static_cast<std::size_t>(layout.size()) * 2);
    for (int i = 0; i < layout.size(); ++i) {
      xy[2 * i] = layout.coord(i, 0);
      xy[2 * i + 1] = layout.coord(i, 1);
    }
    return from_points(xy, pitch_mm);
  }
};

struct BlockShape {
  int h = 1;
  int w = 1;
  friend bool operator==(const BlockShape&, const BlockShape&) = default;
};

// Cell index of a grid placement, and block sampling on it.
class BlockMasker {
 public:
  BlockMasker() = default;
  explicit BlockMasker(GridPlacement grid) : grid_(std::move(grid)) {
    grid_.validate(grid_.size());
    const int cells = grid_.rows * grid_.cols;
    cell_offsets_.assign(cells + 1, 0);
    for (int i = 0; i < grid_.size(); ++i) ++cell_offsets_[cell(grid_.row[i], grid_.col[i]) + 1];
    for (int c = 0; c < cells; ++c) cell_offsets_[c + 1] += cell_offsets_[c];
    cell_tokens_.resize(grid_.size());
    std::vector<int> fill(cell_offsets_.begin(), cell_offsets_.end() - 1);
    for (int i = 0; i < grid_.size(); ++i) cell_tokens_[fill[cell(grid_.row[i], grid_.col[i])]++] = i;
  }

  const GridPlacement& grid() const { return grid_; }

  // A block shape for a scale range (fraction of the tokens) and an aspect-ratio range (h / w).
  BlockShape sample_shape(const RatioRange& scale, const RatioRange& aspect, Rng& rng) const {
    const double s = rng.uniform(scale.lo, scale.hi);
    const double ar = rng.uniform(aspect.lo, aspect.hi);
    const double occupancy = static_cast<double>(grid_.size()) / (grid_.rows * grid_.cols);
    const double area = s * grid_.size() / occupancy;
    BlockShape b;
    b.h = std::clamp(static_cast<int>(std::lround(std::sqrt(area * ar))), 1, grid_.rows);
    b.w = std::clamp(static_cast<int>(std::lround(std::sqrt(area / ar))), 1, grid_.cols);
    return b;
  }

  // The tokens of the block at (top, left) not in `excluded` (may be null), written to out;
  // returns their count. out must hold every token of the block.
  int tokens_in(int top, int left, BlockShape b, const detail::EpochMarks* excluded,
                std::span<int> out) const {
    int k = 0;
    for (int r = top; r < top + b.h; ++r)
      for (int c = cell(r, left), end = c + b.w; c < end; ++c)
        for (int j = cell_offsets_[c]; j < cell_offsets_[c + 1]; ++j) {
          const int v = cell_tokens_[j];
          if (excluded == nullptr || !excluded->test(v)) out[k++] = v;
        }
    return k;
  }

  // A uniformly placed block; returns its token count (see tokens_in). top/left report the place.
  int sample_block(BlockShape b, Rng& rng, const detail::EpochMarks* excluded, std::span<int> out,
                   int* top = nullptr, int* left = nullptr) const {
    const int t0 = static_cast<int>(rng.below(static_cast<std::uint64_t>(grid_.rows - b.h + 1)));
    const int l0 = static_cast<int>(rng.below(static_cast<std::uint64_t>(grid_.cols - b.w + 1)));
    if (top) *top = t0;
    if (left) *left = l0;
    return tokens_in(t0, l0, b, excluded, out);
  }

 private:
  int cell(int r, int c) const { return r * grid_.cols + c; }

  GridPlacement grid_;
  std::vector<int> cell_offsets_{0}, cell_tokens_;
};

}  // namespace tjepa
