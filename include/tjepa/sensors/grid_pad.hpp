#pragma once
// GridPad: a rectangular pad of rows x cols cells, some of them live (a taxel), with a pitch. Its
// edges join live cells that are 4-neighbours (or 8-neighbours, as an option); the weight is the
// distance between the two cells in mm (pitch along a row, row_pitch across rows).
#include <cmath>
#include <cstdint>
#include <span>
#include <utility>
#include <vector>

#include "tjepa/core/error.hpp"
#include "tjepa/graph/taxel_graph.hpp"

namespace tjepa {

struct GridPad {
  GridPad() = default;
  GridPad(int rows_, int cols_, double pitch_ = 1.0, double row_pitch_ = 0.0)
      : rows(rows_), cols(cols_), pitch(pitch_), row_pitch(row_pitch_) {}
  // Sets the live mask ([rows * cols] row-major, nonzero = taxel).
  GridPad& with_live(std::vector<std::uint8_t> mask) {
    live = std::move(mask);
    return *this;
  }
  GridPad& with_eight_neighbours(bool on = true) {
    eight_neighbours = on;
    return *this;
  }

  int rows = 1;
  int cols = 1;
  std::vector<std::uint8_t> live;  // [rows * cols] row-major, 1 = taxel; empty: every cell is live
  double pitch = 1.0;              // mm between neighbouring columns
  double row_pitch = 0.0;          // mm between neighbouring rows; 0: same as pitch
  bool eight_neighbours = false;   // also join diagonal neighbours

  bool is_live(int r, int c) const {
    return live.empty() || live[static_cast<std::size_t>(r) * cols + c] != 0;
  }
  double dy() const { return row_pitch > 0 ? row_pitch : pitch; }
  int num_live() const {
    int n = 0;
    for (int r = 0; r < rows; ++r)
      for (int c = 0; c < cols; ++c) n += is_live(r, c);
    return n;
  }
  void validate(const char* what = "GridPad") const {
    require<ConfigError>(rows > 0 && cols > 0, what, ": ", rows, " x ", cols, " cells, expected both > 0");
    require<ShapeError>(live.empty() || live.size() == static_cast<std::size_t>(rows) * cols, what,
                        ": live mask has ", live.size(), " cells, expected rows*cols = ",
                        static_cast<std::size_t>(rows) * cols);
    require<ConfigError>(std::isfinite(pitch) && pitch > 0, what, ": pitch ", pitch, ", expected > 0");
    require<ConfigError>(std::isfinite(row_pitch) && row_pitch >= 0, what, ": row_pitch ", row_pitch,
                         ", expected >= 0 (0: same as pitch)");
    require<DataError>(num_live() > 0, what, ": no live cell (empty pad)");
  }

  // Taxel index of each cell when the live cells are numbered row-major from `first`; -1 if dead.
  std::vector<int> cell_index(int first = 0) const {
    std::vector<int> idx(static_cast<std::size_t>(rows) * cols, -1);
    for (int r = 0; r < rows; ++r)
      for (int c = 0; c < cols; ++c)
        if (is_live(r, c)) idx[static_cast<std::size_t>(r) * cols + c] = first++;
    return idx;
  }
};

// Edges between live neighbouring cells. cell_index: [rows * cols], the taxel of each cell (-1 for
// a dead cell), e.g. GridPad::cell_index(). Each edge once, src < dst when cell_index is increasing.
inline std::vector<Edge> grid_edges(const GridPad& pad, std::span<const int> cell_index) {
  pad.validate();
  require<ShapeError>(cell_index.size() == static_cast<std::size_t>(pad.rows) * pad.cols,
                      "grid_edges: cell_index has ", cell_index.size(), " entries, expected ",
                      static_cast<std::size_t>(pad.rows) * pad.cols);
  std::vector<Edge> out;
  const double dx = pad.pitch, dy = pad.dy(), dd = std::hypot(dx, dy);
  auto at = [&](int r, int c) { return cell_index[static_cast<std::size_t>(r) * pad.cols + c]; };
  auto add = [&](int a, int b, double w) {
    if (a >= 0 && b >= 0) out.push_back({a, b, w});
  };
  for (int r = 0; r < pad.rows; ++r)
    for (int c = 0; c < pad.cols; ++c) {
      if (!pad.is_live(r, c)) continue;
      const int a = at(r, c);
      if (c + 1 < pad.cols && pad.is_live(r, c + 1)) add(a, at(r, c + 1), dx);
      if (r + 1 < pad.rows && pad.is_live(r + 1, c)) add(a, at(r + 1, c), dy);
      if (pad.eight_neighbours && r + 1 < pad.rows) {
        if (c + 1 < pad.cols && pad.is_live(r + 1, c + 1)) add(a, at(r + 1, c + 1), dd);
        if (c > 0 && pad.is_live(r + 1, c - 1)) add(a, at(r + 1, c - 1), dd);
      }
    }
  return out;
}

}  // namespace tjepa
